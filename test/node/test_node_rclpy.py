"""The arm_sim node on rclpy: the dds tests' scenarios where ROS 2 Jazzy is sourced.

Skips cleanly where rclpy cannot be imported. Each test has its own context and domain id,
localhost discovery tagged with this process (concurrent runs never meet), and drives the
node's ticks itself (its timers are cancelled), so the results do not depend on wall time.
Expected values come from a core Simulator. The last test runs the dds transport as its own
process and talks to it from rclpy: the two Cyclone versions must meet on the wire.
"""
import math
import os
import subprocess
import sys
import time

import pytest

rclpy = pytest.importorskip("rclpy")

from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from builtin_interfaces.msg import Time  # noqa: E402
from hypothesis import assume, given, settings, strategies as st  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402

from arm_sim_ros.interface import split_stamp  # noqa: E402
from arm_sim_ros.node.diagnostics import JointStateData  # noqa: E402
from arm_sim_ros.node.params import parameters as node_params  # noqa: E402
from arm_sim_ros.node.transports import rclpy_transport  # noqa: E402
from arm_sim_ros.node.transports.rclpy_transport import ArmSimNode  # noqa: E402
from arm_sim_ros.node.wire.cdr import clock_cdr, joint_state_bytes  # noqa: E402
from node.node_oracle import assert_matches, expected_states  # noqa: E402

TIMEOUT = 5.0
# rmw_cyclonedds appends CYCLONEDDS_URI to its own configuration, as the dds transport does.
DISCOVERY_TAG = (f"<CycloneDDS><Domain><Discovery><Tag>arm_sim_test_node_rclpy_{os.getpid()}"
                 "</Tag></Discovery></Domain></CycloneDDS>")


class FakeClock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


@pytest.fixture
def ros(request, monkeypatch):
    """(make_node, peer) on a private domain; everything is shut down afterwards."""
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("CYCLONEDDS_URI", DISCOVERY_TAG)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=request.param)
    executor = SingleThreadedExecutor(context=context)
    peer = Peer(context, executor)
    nodes = []

    def make_node(clock=None, **parameters):
        node = ArmSimNode(wall_clock=clock or FakeClock(), context=context, parameter_overrides=[
            Parameter(name, value=value) for name, value in parameters.items()])
        node.tick_timer.cancel()          # the test drives the ticks
        node.diagnostics_timer.cancel()
        executor.add_node(node)
        nodes.append(node)
        peer.wait_matched()
        return node

    yield make_node, peer
    for node in nodes:
        node.destroy_node()
    peer.node.destroy_node()
    executor.shutdown()
    rclpy.shutdown(context=context)


class Peer:
    def __init__(self, context, executor):
        self.executor = executor
        self.node = rclpy.create_node("peer", context=context)
        self.commands = self.node.create_publisher(Float64MultiArray, "joint_torque_commands", 10)
        self.joint_states, self.diagnostics = [], []
        self.node.create_subscription(JointState, "joint_states", self.joint_states.append, 1000)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self.diagnostics.append, 10)
        executor.add_node(self.node)

    def spin_until(self, condition):
        deadline = time.monotonic() + TIMEOUT
        while not condition():
            assert time.monotonic() < deadline, "no delivery on localhost"
            self.executor.spin_once(timeout_sec=0.01)

    def wait_matched(self):
        self.spin_until(lambda: self.commands.get_subscription_count() > 0
                        and self.node.count_publishers("joint_states") > 0)

    def send(self, node, data):
        """Publish one command and spin until the node's subscription callback has run."""
        before = node.core.received_commands
        self.commands.publish(Float64MultiArray(data=[float(v) for v in data]))
        self.spin_until(lambda: node.core.received_commands > before)


def run_ticks(node, peer, schedule):
    for command in schedule:
        if command is not None:
            peer.send(node, command)
        node.on_tick()
    peer.spin_until(lambda: len(peer.joint_states) >= len(schedule))
    return peer.joint_states


@pytest.mark.parametrize("ros", [21], indirect=True)
def test_joint_states_match_the_core_stepped_with_the_same_held_commands(ros):
    make_node, peer = ros
    node = make_node(step_size=0.001, publish_rate=100)   # an integer rate, as -p gives it
    schedule = [(1.0, -0.5)] + [None] * 9 + [(0.0, 2.0)] + [None] * 9
    received = run_ticks(node, peer, schedule)
    assert_matches(received, expected_states(node.core.config.scene, schedule, 10))
    assert list(received[0].name) == ["shoulder_joint", "elbow_joint"]
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in received]
    assert {b - a for a, b in zip(stamps, stamps[1:])} == {10_000_000}


@pytest.mark.parametrize("ros", [27], indirect=True)
def test_on_rmw_cyclonedds_the_node_publishes_the_bytes_and_a_message_gives_the_same(ros):
    """The JointState and Clock go out as the bytes cdr.py writes (the RMW serializes a
    message to the same bytes: rmw_writes_our_cdr); as messages, the same JointStates."""
    make_node, peer = ros
    assert rclpy_transport.rmw_writes_our_cdr()
    schedule = [(1.0, -0.5)] + [None] * 4 + [(0.0, 2.0)] + [None] * 4
    node = make_node(step_size=0.001, publish_rate=100.0)
    assert node.serialized
    node.serialized = False          # what an RMW that serializes otherwise gets
    received = run_ticks(node, peer, schedule)
    assert_matches(received, expected_states(node.core.config.scene, schedule, 10))


names = st.lists(st.text(max_size=12), max_size=4)
doubles = st.lists(st.floats(allow_nan=False, width=64), max_size=4)


@settings(max_examples=100, deadline=None, derandomize=True)
@given(stamp_ns=st.integers(0, 2**31 * 10**9 - 1), frame_id=st.text(max_size=9), name=names,
       position=doubles, velocity=doubles, effort=doubles)
def test_the_rmw_serializes_a_joint_state_and_a_clock_to_the_bytes_the_node_writes(
        stamp_ns, frame_id, name, position, velocity, effort):
    """Every stamp a Time holds; any strings but those with a NUL, which the RMW cuts short
    (the node publishes those as messages: the next test)."""
    assume("\0" not in frame_id + "".join(name))
    data = JointStateData(stamp_ns, frame_id, name, position, velocity, effort)
    sec, nanosec = split_stamp(stamp_ns)
    assert (serialize_message(rclpy_transport.to_joint_state(data))
            == joint_state_bytes(sec, nanosec, frame_id, name, position, velocity, effort))
    assert serialize_message(Clock(clock=Time(sec=sec, nanosec=nanosec))) == clock_cdr(sec,
                                                                                       nanosec)


@pytest.mark.parametrize("ros", [28], indirect=True)
def test_a_name_with_a_nul_goes_out_as_a_message_as_the_rmw_cuts_it(ros):
    make_node, peer = ros
    node = make_node(step_size=0.001, publish_rate=100.0, joint_names=["shoulder\0x", "elbow"])
    received = run_ticks(node, peer, [None])
    assert list(received[0].name) == ["shoulder", "elbow"]


@pytest.mark.parametrize("ros", [22], indirect=True)
def test_bad_commands_are_refused_and_the_last_good_command_holds(ros):
    make_node, peer = ros
    node = make_node(gravity=0.0)
    good = (1.0, 0.5)
    received = run_ticks(node, peer, [good, [math.nan, 0.0], [1.0], [0.0, math.inf], [99.0, 0.0]])
    assert node.core.refused_commands == 4
    assert_matches(received, expected_states(node.core.config.scene, [good] + [None] * 4, 1))


@pytest.mark.parametrize("ros", [23], indirect=True)
def test_command_timeout_drops_torque_to_zero(ros):
    make_node, peer = ros
    node = make_node(gravity=0.0, command_timeout=0.05)
    received = run_ticks(node, peer, [(2.0, 0.0)] + [None] * 9)
    assert [list(m.effort) for m in received] == [[2.0, 0.0]] * 5 + [[0.0, 0.0]] * 5
    assert node.core.command_timeouts == 1


@pytest.mark.parametrize("ros", [24], indirect=True)
def test_parameter_callback_refuses_bad_values_and_keeps_the_old_ones(ros):
    make_node, _ = ros
    node = make_node()
    for name, value in (("damping", -1.0), ("publish_rate", 33.0), ("joint_names", ["a"])):
        result, = node.set_parameters([Parameter(name, value=value)])
        assert not result.successful and name in result.reason
    assert node.get_parameter("damping").value == 0.0
    assert node.core.config.values["publish_rate"] == 100.0
    result, = node.set_parameters([Parameter("torque_limit", value=10.0)])
    assert result.successful and node.core.config.values["torque_limit"] == 10.0


@pytest.mark.parametrize("ros", [25], indirect=True)
def test_start_with_a_bad_parameter_is_refused(ros):
    make_node, _ = ros
    with pytest.raises(node_params.ParameterRefused, match="publish_rate"):
        make_node(publish_rate=33.0)


@pytest.mark.parametrize("ros", [26], indirect=True)
def test_diagnostics_and_reset_service(ros):
    make_node, peer = ros
    clock = FakeClock()
    node = make_node(clock)
    for k in range(50):
        clock.now = 100.0 + 0.01 * k
        node.on_tick()
    peer.send(node, [math.nan, 0.0])
    clock.now = 101.0
    node.on_diagnostics()
    peer.spin_until(lambda: peer.diagnostics)
    status, = peer.diagnostics[0].status
    values = {kv.key: kv.value for kv in status.values}
    assert status.level == DiagnosticStatus.WARN and values["refused_commands"] == "1"
    assert float(values["real_time_factor"]) == pytest.approx(0.49)   # from the first tick done

    client = peer.node.create_client(Trigger, "/arm_sim/reset")
    assert client.wait_for_service(timeout_sec=TIMEOUT)
    future = client.call_async(Trigger.Request())
    peer.spin_until(future.done)
    assert future.result().success and node.core.sim.steps == 0


def test_a_dds_transport_node_started_first_is_found_by_a_later_rclpy_peer(monkeypatch):
    """`arm_sim_node --transport dds` already running when a ROS 2 node starts, as in
    `ros2 topic echo /joint_states`: the peer sees /arm_sim, its JointStates and its reply to a
    torque command. (Cyclone 11 once ignored the late rmw peer's announcement on 127.0.0.1.)"""
    env = dict(os.environ, ROS_DOMAIN_ID="27", ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               CYCLONEDDS_URI=DISCOVERY_TAG)
    process = subprocess.Popen(
        [sys.executable, "-m", "arm_sim_ros.node.main", "--transport", "dds", "--duration", "60",
         "--ros-args", "-p", "gravity:=0.0"],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        assert "scene release started" in process.stderr.readline()   # its endpoints exist
        for name in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "CYCLONEDDS_URI"):
            monkeypatch.setenv(name, env[name])
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=27)
        executor = SingleThreadedExecutor(context=context)
        try:
            peer = Peer(context, executor)
            peer.spin_until(lambda: peer.joint_states and ("arm_sim", "/")
                            in peer.node.get_node_names_and_namespaces())   # ros2 node list
            assert list(peer.joint_states[0].name) == ["shoulder_joint", "elbow_joint"]

            def pushed():
                peer.commands.publish(Float64MultiArray(data=[1.0, 0.0]))
                return list(peer.joint_states[-1].effort) == [1.0, 0.0]
            peer.spin_until(pushed)
            peer.node.destroy_node()
        finally:
            executor.shutdown()
            rclpy.shutdown(context=context)
        process.terminate()                    # SIGTERM ends the node as Ctrl-C does
        _, err = process.communicate(timeout=TIMEOUT)
    finally:
        process.kill()
    assert process.returncode == 0, err
    assert "torque command [1.0, 0.0] N m" in err and "refused torque command" not in err
    assert "0 commands refused" in err                 # the stop line says so


@pytest.mark.parametrize("ros", [29], indirect=True)
def test_a_set_the_core_cannot_apply_is_refused_and_the_node_goes_on(ros, monkeypatch):
    """A rebuild that raises (here an overflow, as a payload of 1e200 kg far out on the arm
    once did) is answered as refused, as on dds, instead of ending the node through spin."""
    make_node, peer = ros
    node = make_node()

    def overflow(changes):
        raise OverflowError(34, "Numerical result out of range")

    with monkeypatch.context() as patch:
        patch.setattr(node.core, "set_parameters", overflow)
        result = node.set_parameters([Parameter("damping", value=0.3)])[0]
    assert not result.successful
    assert result.reason == ("parameters damping refused: the node could not apply them "
                             "(OverflowError); nothing changed")
    assert node.set_parameters([Parameter("damping", value=0.3)])[0].successful
    node.on_tick()
    peer.spin_until(lambda: peer.joint_states)


@pytest.mark.parametrize("ros", [165], indirect=True)
def test_sensors_readings_and_truth_are_the_offline_simulators_bit_for_bit(ros):
    """/joint_states carries the readings, /arm_sim/true_joint_states the truth, same stamps,
    equal to what the offline simulator reads after each tick (as on dds)."""
    from node.test_sensors_node import SENSORS, offline

    make_node, peer = ros
    truths = []
    peer.node.create_subscription(JointState, "/arm_sim/true_joint_states", truths.append, 1000)
    node = make_node(**(SENSORS | {"publish_rate": 250.0, "step_size": 0.001,
                                   "policy": "command_gravity_compensation"}))
    node.on_tick()                        # the truth's publisher comes with the first truth
    peer.spin_until(lambda: peer.node.count_publishers("/arm_sim/true_joint_states") > 0)
    peer.send(node, (0.5, -0.2))
    for _ in range(39):
        node.on_tick()
    peer.spin_until(lambda: len(peer.joint_states) >= 40 and truths and
                    truths[-1].header.stamp == peer.joint_states[-1].header.stamp)
    expected = offline(node.core, 40, commands={1: (0.5, -0.2)})
    assert [list(m.position) + list(m.velocity) for m in peer.joint_states] == [
        r for r, _ in expected]
    first = 40 - len(truths)
    assert [list(m.position) + list(m.velocity) for m in truths] == [
        s for _, s in expected[first:]]
    assert [m.header.stamp for m in truths] == [m.header.stamp for m in peer.joint_states[first:]]
