"""The SimulateSteps action on the dds transport, as rcl_action lays an action out on
rmw_cyclonedds: three services under `<namespace>/simulate_steps/_action/` (send_goal,
get_result, cancel_goal; each as dds_services.py serves a service) and two topics there
(feedback; status, reliable and transient-local keep-last 1 as
rcl_action_qos_profile_status_default). Wire type names as rosidl generates them for an
action (`simulation_interfaces::action::dds_::SimulateSteps_SendGoal_Request_`; cancel_goal
and status are action_msgs'), USER_DATA with their RIHS01 hashes. A get_result request is
answered once its goal has finished. The goals themselves: node/services/simulate_steps.py. (No
`from __future__ import annotations`: cyclonedds resolves field types at runtime.)
"""

from dataclasses import dataclass, field

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.annotations import final
from cyclonedds.idl.types import array, int8, sequence, uint8, uint64
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from ...interface import split_stamp
from ..wire import messages as msg
from ..wire.service_types import ros_type_names, service
from ..services import simulate_steps as steps
from .dds_simulation import Result as ActionResult   # simulation_interfaces/msg/Result


@final
@dataclass
class UUID(IdlStruct, typename="unique_identifier_msgs.msg.dds_.UUID_"):
    uuid: array[uint8, 16] = field(default_factory=lambda: [0] * 16)


@final
@dataclass
class GoalInfo(IdlStruct, typename="action_msgs.msg.dds_.GoalInfo_"):
    goal_id: UUID = field(default_factory=UUID)
    stamp: msg.Time = field(default_factory=msg.Time)


@final
@dataclass
class GoalStatus(IdlStruct, typename="action_msgs.msg.dds_.GoalStatus_"):
    goal_info: GoalInfo = field(default_factory=GoalInfo)
    status: int8 = 0


@final
@dataclass
class GoalStatusArray(IdlStruct, typename="action_msgs.msg.dds_.GoalStatusArray_"):
    status_list: sequence[GoalStatus] = field(default_factory=list)


@final
@dataclass
class Goal(IdlStruct, typename="simulation_interfaces.action.dds_.SimulateSteps_Goal_"):
    steps: uint64 = 0


@final
@dataclass
class Result(IdlStruct, typename="simulation_interfaces.action.dds_.SimulateSteps_Result_"):
    result: ActionResult = field(default_factory=ActionResult)


@final
@dataclass
class Feedback(IdlStruct, typename="simulation_interfaces.action.dds_.SimulateSteps_Feedback_"):
    completed_steps: uint64 = 0
    remaining_steps: uint64 = 0


@final
@dataclass
class FeedbackMessage(IdlStruct,
                      typename="simulation_interfaces.action.dds_.SimulateSteps_FeedbackMessage_"):
    goal_id: UUID = field(default_factory=UUID)
    feedback: Feedback = field(default_factory=Feedback)


# --- the services (wire/service_types.py: rmw_cyclonedds' request header first) ------------

SendGoalRequest, SendGoalResponse = service(
    "simulation_interfaces/action/SimulateSteps_SendGoal",
    {"goal_id": UUID, "goal": Goal}, {"accepted": bool, "stamp": msg.Time})
GetResultRequest, GetResultResponse = service(
    "simulation_interfaces/action/SimulateSteps_GetResult",
    {"goal_id": UUID}, {"status": int8, "result": Result})
CancelGoalRequest, CancelGoalResponse = service(
    "action_msgs/srv/CancelGoal",
    {"goal_info": GoalInfo}, {"return_code": int8, "goals_canceling": sequence[GoalInfo]})


ACTION = "simulate_steps"
PREFIX = f"{ACTION}/_action/"
SERVICES = tuple(PREFIX + name for name in ("send_goal", "cancel_goal", "get_result"))
TYPES = dict(zip(SERVICES, ((SendGoalRequest, SendGoalResponse),
                            (CancelGoalRequest, CancelGoalResponse),
                            (GetResultRequest, GetResultResponse))))   # service: its types
ROS_TYPE_NAMES = {
    FeedbackMessage: "simulation_interfaces/action/SimulateSteps_FeedbackMessage",
    GoalStatusArray: "action_msgs/msg/GoalStatusArray",
} | ros_type_names((SendGoalRequest, SendGoalResponse), (GetResultRequest, GetResultResponse),
                   (CancelGoalRequest, CancelGoalResponse))
# RIHS01 hashes (REP 2011) of the definitions (SimulateSteps.action, jazzy branch; action_msgs,
# unique_identifier_msgs, builtin_interfaces of Jazzy); test_simulate_steps checks each.
TYPE_HASHES = {
    "action_msgs/srv/CancelGoal_Request":
        "RIHS01_3d3c84653c1f96918086887e1dcb236faec88b81a5b14fd4cf4840065bcdf8af",
    "action_msgs/srv/CancelGoal_Response":
        "RIHS01_35e682cf3f510e83c70a82a4aac888496dedee56773bf9d8e5e0aa81f9e1c960",
    "simulation_interfaces/action/SimulateSteps_SendGoal_Request":
        "RIHS01_275e6fd2fafc5d33dcdc83bdea6de5cf29f30b9df74a3b9514a8c5d501fd0fe3",
    "simulation_interfaces/action/SimulateSteps_SendGoal_Response":
        "RIHS01_755f44a68d1e8d116f50dfed7ab30a140137fb71ad59eca4851d55abe2b3d4c2",
    "simulation_interfaces/action/SimulateSteps_GetResult_Request":
        "RIHS01_4591b0bfbcb881003bbd46a2acebcaddceb977e5352905218688ce5ed051fdeb",
    "simulation_interfaces/action/SimulateSteps_GetResult_Response":
        "RIHS01_5658172e771cb145a986a8ef4c2b80b5407b741038453b8539e35bed5ff23207",
    "simulation_interfaces/action/SimulateSteps_FeedbackMessage":
        "RIHS01_a30dee7ee7380769e616406ec5067b238aa2b27e1dbd7a5957fba1d908d7754d",
    "action_msgs/msg/GoalStatusArray":
        "RIHS01_6c1684b00f177d37438febe6e709fc4e2b0d4248dca4854946f9ed8b30cda83e",
}


def topic_qos(message_type, durability, depth: int) -> Qos:
    """rmw_cyclonedds' QoS of a reliable keep-last topic, USER_DATA with its type hash."""
    typehash = TYPE_HASHES[ROS_TYPE_NAMES[message_type]]
    return Qos(Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
               durability, Policy.History.KeepLast(depth),
               Policy.WriterDataLifecycle(autodispose=False),
               Policy.Userdata(f"typehash={typehash};".encode()))


def goal_info(goal) -> GoalInfo:
    return GoalInfo(UUID(list(goal.goal_id)), msg.Time(*split_stamp(goal.stamp_ns)))


class DdsSimulateSteps:
    """The action's services (for DdsServices) and topics; `attach` a SimulationControl and
    the way to answer a request later, then `advance()` between polls: one tick."""

    def __init__(self, participant, resolve, clock_ns):
        self.clock_ns, self.goals, self.reply_later = clock_ns, None, None
        self.waiting = {}     # goal id -> get_result requests not answered yet

        def writer(name, kind, durability, depth):
            topic = msg.ros_topic(resolve(PREFIX + name))
            return DataWriter(participant, Topic(participant, topic, kind),
                              qos=topic_qos(kind, durability, depth))

        self.feedback_writer = writer("feedback", FeedbackMessage, Policy.Durability.Volatile, 10)
        self.status_writer = writer("status", GoalStatusArray, Policy.Durability.TransientLocal, 1)

    @property
    def writers(self) -> list:
        return [self.feedback_writer, self.status_writer]

    def services(self) -> list:
        """(service, request type, response type, handler) for DdsServices."""
        handlers = (self._send_goal, self._cancel, self._result)
        return [(name, *TYPES[name], handler) for name, handler in zip(SERVICES, handlers)]

    def attach(self, control, reply_later) -> None:
        """`reply_later(service, reply, request)`: send `reply` to the client of `request`."""
        self.goals, self.reply_later = steps.StepsGoals(control, self.clock_ns), reply_later

    def close(self) -> None:
        """Leave the graph: no goal goes on, the writers go (cyclonedds deletes an entity when
        its last reference goes)."""
        self.goals = self.feedback_writer = self.status_writer = None
        self.waiting = {}

    @property
    def busy(self) -> bool:
        return self.goals is not None and self.goals.active() is not None

    def advance(self) -> None:
        """One tick of the executing goal and its feedback; the status list when it changed;
        the results waited for, of goals that finished."""
        goals = self.goals
        if goals is None or not (goals.goals or goals.changed or self.waiting):
            return                  # no goal: the node polls here every tick, and goes on
        goal = goals.advance(listening=bool(msg.matched(self.feedback_writer)))
        if goal is not None:
            self.feedback_writer.write(FeedbackMessage(UUID(list(goal.goal_id)), Feedback(
                goal.completed, goal.remaining)))
        if self.goals.changed:
            self.status_writer.write(GoalStatusArray([
                GoalStatus(goal_info(g), g.status) for g in self.goals.status_list()]))
        for goal_id in [k for k in self.waiting if self.goals.result(k) is not None]:
            for request in self.waiting.pop(goal_id):
                self.reply_later(PREFIX + "get_result", self._reply(request), request)

    # handlers: request -> the reply's fields (None: answered later) ------------------------

    def _send_goal(self, request) -> dict:
        goal = self.goals.send_goal(bytes(request.goal_id.uuid), request.goal.steps)
        stamp = goal.stamp_ns if goal is not None else self.clock_ns()
        return {"accepted": goal is not None, "stamp": msg.Time(*split_stamp(stamp))}

    def _cancel(self, request) -> dict:
        info = request.goal_info
        code, goals = self.goals.cancel(bytes(info.goal_id.uuid),
                                        info.stamp.sec * 10**9 + info.stamp.nanosec)
        return {"return_code": code, "goals_canceling": [goal_info(g) for g in goals]}

    def _result(self, request) -> dict | None:
        goal_id = bytes(request.goal_id.uuid)
        if self.goals.result(goal_id) is None:        # still running: when it finishes
            self.waiting.setdefault(goal_id, []).append(request)
            return None
        reply = self._reply(request)
        return {"status": reply.status, "result": reply.result}

    def _reply(self, request) -> GetResultResponse:
        status, code, message = self.goals.result(bytes(request.goal_id.uuid))
        return GetResultResponse(guid=request.guid, seq=request.seq, status=status,
                                 result=Result(ActionResult(code, message)))
