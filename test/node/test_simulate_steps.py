"""The SimulateSteps action on the dds transport, tested on the wire with no ROS: a client
writes rcl_action's requests on rmw_cyclonedds' service layout (send_goal, get_result,
cancel_goal under simulate_steps/_action/) and reads the feedback and status topics."""
from __future__ import annotations

import time
import uuid

from cyclonedds.qos import Policy
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from arm_sim_ros.node.wire import messages as msg
from arm_sim_ros.node.services import simulate_steps as a
from arm_sim_ros.node.services import simulation as s
from arm_sim_ros.node.transports import dds_action as d
from arm_sim_ros.node.transports import dds_simulation
from arm_sim_ros.tools.wire.sim_client import SimulationClient
from node.test_dds_services import Client, start
from node.test_node_dds import CONFIG, FakeClock, wait_until
from node.test_simulation_interfaces import read, readers, sim_client

# The definitions the hashes cover (fields only): SimulateSteps.action (simulation_interfaces,
# jazzy branch) as rosidl splits an action, and action_msgs' CancelGoal (Jazzy).
DEFINITIONS = {
    "simulation_interfaces/action/SimulateSteps_Goal": "uint64 steps",
    "simulation_interfaces/action/SimulateSteps_Result": "simulation_interfaces/msg/Result result",
    "simulation_interfaces/action/SimulateSteps_Feedback":
        "uint64 completed_steps\nuint64 remaining_steps",
    "action_msgs/srv/CancelGoal_Request": "action_msgs/msg/GoalInfo goal_info",
    "action_msgs/srv/CancelGoal_Response":
        "int8 return_code\naction_msgs/msg/GoalInfo[] goals_canceling",
}
SERVICES = {
    "simulation_interfaces/action/SimulateSteps_SendGoal_Request":
        "unique_identifier_msgs/msg/UUID goal_id\nsimulation_interfaces/action/SimulateSteps_Goal goal",
    "simulation_interfaces/action/SimulateSteps_SendGoal_Response":
        "bool accepted\nbuiltin_interfaces/msg/Time stamp",
    "simulation_interfaces/action/SimulateSteps_GetResult_Request":
        "unique_identifier_msgs/msg/UUID goal_id",
    "simulation_interfaces/action/SimulateSteps_GetResult_Response":
        "int8 status\nsimulation_interfaces/action/SimulateSteps_Result result",
    "simulation_interfaces/action/SimulateSteps_FeedbackMessage":
        "unique_identifier_msgs/msg/UUID goal_id\n"
        "simulation_interfaces/action/SimulateSteps_Feedback feedback",
}


def register(store, definitions):
    types = {}
    for name, text in definitions.items():
        (_, definition), = get_types_from_msg(text, name).items()
        types[name] = definition
    store.register(types)


def test_type_hashes_are_rosidls():
    store = get_typestore(Stores.ROS2_JAZZY)     # action_msgs' messages, UUID, Time: Jazzy's
    store.register(get_types_from_msg("uint8 result\nstring error_message",
                                      "simulation_interfaces/msg/Result"))
    register(store, DEFINITIONS)
    register(store, SERVICES)
    assert {name: store.hash_rihs01(name) for name in d.TYPE_HASHES} == d.TYPE_HASHES


def test_wire_type_names_are_rosidls():
    for kind, name in d.ROS_TYPE_NAMES.items():
        package, sort, typename = name.split("/")
        assert kind.__idl_typename__ == f"{package}.{sort}.dds_.{typename}_"
    assert d.SendGoalRequest().guid == 0 and d.CancelGoalResponse().seq == 0


def action_client(peer, service, types):
    client = Client(peer, d.PREFIX + service, node_name="", types=types)
    client.wait_for_service()
    return client


class ActionClient:
    """rcl_action's client, on the wire: its three services, feedback and status."""

    def __init__(self, node, peer):
        self.node = node
        self.send_goal = action_client(peer, "send_goal", (d.SendGoalRequest, d.SendGoalResponse))
        self.get_result = action_client(peer, "get_result",
                                        (d.GetResultRequest, d.GetResultResponse))
        self.cancel_goal = action_client(peer, "cancel_goal",
                                         (d.CancelGoalRequest, d.CancelGoalResponse))
        self.feedback = DataReader(peer, Topic(peer, f"rt/{d.PREFIX}feedback", d.FeedbackMessage),
                                   qos=d.topic_qos(d.FeedbackMessage, Policy.Durability.Volatile,
                                                   1000))
        # status as rcl_action's client reads it: transient-local (a late joiner sees the last)
        self.status = DataReader(peer, Topic(peer, f"rt/{d.PREFIX}status", d.GoalStatusArray),
                                 qos=d.topic_qos(d.GoalStatusArray,
                                                 Policy.Durability.TransientLocal, 1000))
        wait_until(lambda: msg.matched(node.services.action.feedback_writer)
                   and msg.matched(node.services.action.status_writer), "action topics")

    def send(self, steps: int) -> tuple:
        goal_id = d.UUID(list(uuid.uuid4().bytes))
        reply = self.send_goal.call(self.node, goal_id=goal_id, goal=d.Goal(steps))
        return goal_id, reply

    def result(self, goal_id):
        return self.get_result.call(self.node, goal_id=goal_id)

    def cancel(self, goal_id=None, stamp=msg.Time()):
        info = d.GoalInfo(goal_id or d.UUID(), stamp)
        return self.cancel_goal.call(self.node, goal_info=info)

    def feedback_of(self, goal_id) -> list:
        return [(m.feedback.completed_steps, m.feedback.remaining_steps)
                for m in self.feedback.take(N=10000)
                if isinstance(m, d.FeedbackMessage) and bytes(m.goal_id.uuid) == bytes(goal_id.uuid)]


def paused_node(domain_id):
    node, peer = start(domain_id, scene="servo_hold", publish_rate=100.0)
    set_state = sim_client(peer, "set_simulation_state")
    reply = set_state.call(node, state=dds_simulation.SimulationState(s.STATE_PAUSED))
    assert reply.result.result == s.RESULT_OK
    return node, peer, set_state


def test_a_goal_steps_exactly_n_ticks_with_feedback_after_each_and_returns_the_result():
    node, peer, _ = paused_node(150)
    joint_states, clock = readers(peer)
    client = ActionClient(node, peer)
    before = node.core.sim.steps
    goal_id, reply = client.send(5)
    assert reply.accepted and reply.stamp.sec > 0
    result = client.result(goal_id)                 # asked while it runs: answered at its end
    assert result.status == a.STATUS_SUCCEEDED
    assert (result.result.result.result, result.result.result.error_message) == (s.RESULT_OK, "")
    assert node.core.sim.steps == before + 5 * node.core.config.steps_per_tick
    assert node.core.paused
    time.sleep(0.05)
    assert client.feedback_of(goal_id) == [(k, 5 - k) for k in range(1, 6)]
    assert len(read(joint_states, msg.JointState, 5)) == 5     # each tick published
    statuses = [[(bytes(g.goal_info.goal_id.uuid), g.status) for g in m.status_list]
                for m in client.status.take(N=100) if isinstance(m, d.GoalStatusArray)]
    assert statuses[-1] == [(bytes(goal_id.uuid), a.STATUS_SUCCEEDED)]
    assert (bytes(goal_id.uuid), a.STATUS_EXECUTING) in [entry for m in statuses for entry in m]
    assert client.result(goal_id).status == a.STATUS_SUCCEEDED     # kept: asked again
    assert client.send(5)[1].accepted and client.send_goal.call(
        node, goal_id=goal_id, goal=d.Goal(1)).accepted is False    # an id used before


def test_a_cancel_stops_the_goal_between_two_ticks():
    node, peer, _ = paused_node(151)
    client = ActionClient(node, peer)
    before = node.core.sim.steps
    goal_id, reply = client.send(100_000)
    assert reply.accepted
    for _ in range(3):
        node.services.poll()                        # three ticks
    canceled = client.cancel(goal_id)
    assert canceled.return_code == a.ERROR_NONE
    assert [bytes(g.goal_id.uuid) for g in canceled.goals_canceling] == [bytes(goal_id.uuid)]
    result = client.result(goal_id)
    assert result.status == a.STATUS_CANCELED and result.result.result.result == s.RESULT_OK
    ticks = (node.core.sim.steps - before) // node.core.config.steps_per_tick
    assert 3 <= ticks < 100 and f"canceled after {ticks} of 100000" in (
        result.result.result.error_message)
    for _ in range(5):
        node.services.poll()
    assert (node.core.sim.steps - before) // node.core.config.steps_per_tick == ticks  # stopped
    assert client.cancel(goal_id).return_code == a.ERROR_GOAL_TERMINATED
    assert client.cancel(d.UUID(list(range(16)))).return_code == a.ERROR_UNKNOWN_GOAL_ID
    # a zero id and stamp: every goal
    first, _ = client.send(100_000)
    node.services.poll()
    everything = client.cancel()
    assert [bytes(g.goal_id.uuid) for g in everything.goals_canceling] == [bytes(first.uuid)]
    assert client.result(first).status == a.STATUS_CANCELED


def aborted(client, goal_id) -> str:
    """The error message of a goal that was aborted with RESULT_OPERATION_FAILED."""
    reply = client.result(goal_id)
    assert reply.status == a.STATUS_ABORTED
    assert reply.result.result.result == s.RESULT_OPERATION_FAILED
    return reply.result.result.error_message


def test_a_goal_while_playing_or_while_another_runs_is_aborted_saying_why():
    node, peer, set_state = paused_node(152)
    client = ActionClient(node, peer)
    running, _ = client.send(100_000)
    second, reply = client.send(3)
    assert reply.accepted
    assert "another simulate_steps goal is running" in aborted(client, second)
    # set playing meanwhile: the running goal stops at its next tick
    set_state.call(node, state=dds_simulation.SimulationState(s.STATE_PLAYING))
    assert "interrupted after" in aborted(client, running)
    steps = node.core.sim.steps
    playing, reply = client.send(10)
    assert reply.accepted
    assert "needs the simulation paused" in aborted(client, playing)
    assert node.core.sim.steps == steps                # nothing stepped


def test_stopping_aborts_a_running_goal_and_it_ticks_no_more():
    """Issue 39: set_simulation_state(STOPPED) during a goal reset the arm and left the goal
    ticking from the reset state."""
    node, peer, set_state = paused_node(212)
    client = ActionClient(node, peer)
    running, _ = client.send(100_000)
    for _ in range(3):
        node.services.poll()
    reply = set_state.call(node, state=dds_simulation.SimulationState(s.STATE_STOPPED))
    assert reply.result.result == s.RESULT_OK
    assert aborted(client, running).endswith("of 100000 steps: set stopped")
    for _ in range(5):
        node.services.poll()
    assert node.core.sim.steps == 0 and node.core.paused


def test_a_step_call_and_a_goal_do_not_tick_at_once():
    node, peer, _ = paused_node(213)
    client, step = ActionClient(node, peer), sim_client(peer, "step_simulation")
    running, _ = client.send(100_000)
    node.services.poll()
    refused = step.call(node, steps=5).result
    assert (refused.result, refused.error_message) == (s.RESULT_OPERATION_FAILED,
                                                     "a simulate_steps goal is running")
    client.cancel(running)
    assert client.result(running).status == a.STATUS_CANCELED
    step.send(steps=50)
    node.services.poll()
    second, _ = client.send(3)
    assert "a step_simulation call is running" in aborted(client, second)
    assert step.replies(node)[0].result.result == s.RESULT_OK


def test_features_list_the_action():
    node, peer = start(153)
    reply = sim_client(peer, "get_simulator_features").call(node)
    assert s.STEP_SIMULATION_ACTION in reply.features.features


def test_the_harness_client_runs_the_action():
    node, _ = start(154, scene="servo_hold")
    harness = SimulationClient(domain_id=154, config=CONFIG, serve=node.services.poll)
    harness.wait_for_node()
    assert harness.pause() == s.RESULT_OK
    before = node.core.sim.steps
    assert harness.simulate(20) == (a.STATUS_SUCCEEDED, s.RESULT_OK, "")
    assert node.core.sim.steps == before + 20 * node.core.config.steps_per_tick
    assert harness.received_feedback() == [(k, 20 - k) for k in range(1, 21)]
    assert len(harness.received_joint_states()) >= 20
    assert harness.play() == s.RESULT_OK
    status, code, message = harness.simulate(5)
    assert (status, code) == (a.STATUS_ABORTED, s.RESULT_OPERATION_FAILED) and "paused" in message


class Control:
    """A paused SimulationControl that counts its ticks."""
    state, ticks, epoch, calls = s.STATE_PAUSED, 0, 0, ()

    def step(self, n):
        self.ticks += n
        return s.RESULT_OK, ""

    def ready(self):               # not in lockstep: a tick may always happen
        return True


def test_a_goals_first_tick_waits_a_moment_for_a_reader_of_its_feedback():
    """A client that has just found the server may not be matched with its feedback yet
    (ros2 action send_goal --feedback showed 2 to 4 of 20): the goal waits for a reader, up
    to FEEDBACK_WAIT, then runs whether or not one came."""
    clock, control = FakeClock(), Control()
    clock.now = 0                                   # ns, as rcl_action stamps
    goals = a.StepsGoals(control, clock)
    goals.send_goal(bytes(range(16)), 3)
    assert goals.advance(listening=False) is None and control.ticks == 0
    clock.now += int(0.9 * a.FEEDBACK_WAIT * 1e9)
    assert goals.advance(listening=False) is None and control.ticks == 0
    assert goals.advance(listening=True).completed == 1             # a reader came
    assert goals.advance(listening=False).completed == 2            # the first tick only
    unheard = a.StepsGoals(control, clock)
    unheard.send_goal(bytes(range(1, 17)), 1)
    clock.now += int(a.FEEDBACK_WAIT * 1e9)
    assert unheard.advance(listening=False).status == a.STATUS_SUCCEEDED   # nobody: runs


def test_a_closed_node_leaves_with_its_action_topics():
    node, peer, _ = paused_node(155)
    client = ActionClient(node, peer)
    node.close()
    wait_until(lambda: not msg.matched(client.status) and not msg.matched(client.feedback),
               "the action's writers still matched after close")
