"""A test harness's client of the node's Simulation Interfaces on the dds transport, with no
ROS installed: each service (the SimulateSteps action's too) called on the wire as an
rmw_cyclonedds client calls it (node/transports/dds_services.py tells the layout), set-point
commands published and acknowledged, and the node's joint_states read. Against rclpy, call
the same services with simulation_interfaces' types."""
from __future__ import annotations

import time
import uuid

from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from ...interface import SETPOINT_TOPICS
from ...node.wire import messages as msg
from ...node.services import simulation as s
from ...node.transports import dds_action as a
from ...node.transports import dds_simulation as d
from ...node.transports.dds_services import cs_id, endpoint_qos

U64 = (1 << 64) - 1
TIMEOUT = 10.0             # s a call waits for the node to be found and to answer


class SimulationClient:
    """Play, pause, stop, step and reset a dds node; command its servos; read its state.
    `serve()`: called while waiting, for a node in this same process (its services' poll)."""

    def __init__(self, domain_id: int | None = None, config: str | None = None,
                 namespace: str = "", serve=None):
        self.participant = p = msg.make_participant(domain_id, config)
        self.serve = serve or (lambda: None)
        kinds = {name: (request, response) for name, (_, request, response) in d.TYPES.items()}
        self.services = {name: _Service(p, f"{namespace}/{name}", request, response, k + 1)
                         for k, (name, (request, response)) in enumerate((kinds | a.TYPES).items())}
        self.commands = {field: DataWriter(p, Topic(p, msg.ros_topic(f"{namespace}/{topic}"),
                                                    msg.Float64MultiArray),
                                           qos=msg.default_qos(msg.Float64MultiArray))
                         for field, topic in SETPOINT_TOPICS.items()}
        self.joint_states = DataReader(p, Topic(p, msg.ros_topic(f"{namespace}/joint_states"),
                                                msg.JointState),
                                       qos=msg.default_qos(msg.JointState, depth=1000))
        # as an rcl_action client: the action's feedback read (a goal waits a moment for it)
        self.feedback = DataReader(p, Topic(p, msg.ros_topic(f"{namespace}/{a.PREFIX}feedback"),
                                            a.FeedbackMessage),
                                   qos=a.topic_qos(a.FeedbackMessage, Policy.Durability.Volatile,
                                                   1000))

    def wait_for_node(self) -> None:
        self._until(lambda: not self.unmatched(), "the node's services and topics")

    def unmatched(self) -> list:
        """The node's services and topics this client has not matched yet, by name."""
        return ([name for name, service in self.services.items() if not service.matched()]
                + [field for field, writer in self.commands.items() if not msg.matched(writer)]
                + [name for name, endpoint in (("joint_states", self.joint_states),
                                               ("feedback", self.feedback))
                   if not msg.matched(endpoint)])

    def call(self, service: str, **fields):
        """The reply to one request (the service's response type)."""
        return self._until(self.services[service].ask(**fields), f"a reply from {service}")

    def state(self) -> int:
        return self.call("get_simulation_state").state.state

    def set_state(self, state: int) -> int:
        return self.call("set_simulation_state", state=d.SimulationState(state)).result.result

    def play(self) -> int:
        return self.set_state(s.STATE_PLAYING)

    def pause(self) -> int:
        return self.set_state(s.STATE_PAUSED)

    def stop(self) -> int:
        """Reset and paused."""
        return self.set_state(s.STATE_STOPPED)

    def reset(self) -> int:
        return self.call("reset_simulation", scope=s.SCOPE_DEFAULT).result.result

    def step(self, ticks: int) -> int:
        return self.call("step_simulation", steps=ticks).result.result

    def simulate(self, ticks: int, timeout: float = TIMEOUT) -> tuple[int, int, str]:
        """The SimulateSteps action: a goal of `ticks`, its end waited for (up to `timeout`
        s); (its status, as action_msgs/GoalStatus has it, result code, message)."""
        goal_id = a.UUID(list(uuid.uuid4().bytes))
        self.call(a.SERVICES[0], goal_id=goal_id, goal=a.Goal(ticks))
        reply = self._until(self.services[a.SERVICES[2]].ask(goal_id=goal_id),
                            "the SimulateSteps result", timeout)
        return reply.status, reply.result.result.result, reply.result.result.error_message

    def command(self, field: str, values) -> None:
        """[joint 1, joint 2] on position_commands or velocity_commands (`field`), held by the
        node once this returns (acknowledged): a step asked for after it acts under it."""
        writer = self.commands[field]
        writer.write(msg.Float64MultiArray(data=[float(v) for v in values]))
        writer.wait_for_acks(duration(seconds=TIMEOUT))

    def received_feedback(self) -> list:
        """(completed, remaining) steps of every SimulateSteps feedback since the last call."""
        self.serve()
        return [(m.feedback.completed_steps, m.feedback.remaining_steps)
                for m in self.feedback.take(N=100_000) if isinstance(m, a.FeedbackMessage)]

    def received_joint_states(self) -> list:
        """Every JointState the node published since the last call."""
        self.serve()
        return [m for m in self.joint_states.take(N=100_000) if isinstance(m, msg.JointState)]

    def _until(self, found, what: str, timeout: float = TIMEOUT):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.serve()
            value = found()
            if value:
                return value
            time.sleep(0.0005)
        raise TimeoutError(f"{what} did not come within {timeout:g} s")


class _Service:
    """One service's request writer and reply reader, as rmw_cyclonedds makes a client's."""

    def __init__(self, participant, name: str, request_type, response_type, counter: int):
        p, user_data = participant, f"clientid={cs_id(participant.guid.bytes, counter)};"
        self.request_type, self.response_type = request_type, response_type
        self.writer = DataWriter(p, Topic(p, f"rq{name}Request", request_type),
                                 qos=endpoint_qos(request_type, 10, user_data))
        self.reader = DataReader(p, Topic(p, f"rr{name}Reply", response_type),
                                 qos=endpoint_qos(response_type, 10, user_data))
        self.guid = self.writer.get_instance_handle() & U64     # rmw: header.guid
        self.seq = 0

    def matched(self) -> bool:
        return bool(msg.matched(self.writer) and msg.matched(self.reader))

    def ask(self, **fields):
        """Send a request; a function that returns its reply once it came, else None."""
        self.seq += 1
        seq = self.seq
        self.writer.write(self.request_type(guid=self.guid, seq=seq, **fields))

        def reply():
            for sample in self.reader.take(N=64):
                if isinstance(sample, self.response_type) and (sample.guid, sample.seq) == (
                        self.guid, seq):
                    return sample
            return None
        return reply
