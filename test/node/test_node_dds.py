"""The arm_sim node on the dds transport, in-process, loopback only, one DDS domain per test.

The test drives the node's ticks and wall clock itself (never wall time) and talks to it
through an independent participant, as any ROS 2 peer would. Expected values come from a
core Simulator stepped with the same held commands.
"""
import logging
import math
import os
import subprocess
import sys
import time
import types

import pytest
from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from rosbags.typesys import Stores, get_typestore

from arm_sim_ros import interface
from arm_sim_ros.node.commands import intake as node_commands
from arm_sim_ros.node import core as node_core, transports
from arm_sim_ros.node.params import parameters as node_params
from arm_sim_ros.node.wire import messages as msg
from arm_sim_ros.node.main import load_params_file, main as node_main, node_parameters, parse_ros_args
from arm_sim_ros.node.transports.dds import DdsArmSimNode
from node.node_oracle import assert_matches, expected_states

TIMEOUT = 5.0   # generous bound on loopback delivery; a passing test waits ~1 ms
# Loopback, tagged with this process: a concurrent run of these tests elsewhere on the machine
# (same domain ids) is never discovered.
CONFIG = msg.loopback_config(f"arm_sim_test_node_dds_{os.getpid()}")


def wait_until(condition, what: str, poll: float = 0.001):
    """Poll `condition()` until it is true (returning its value); fail saying `what` did not
    happen within TIMEOUT."""
    deadline = time.monotonic() + TIMEOUT
    while not (value := condition()):
        assert time.monotonic() < deadline, what
        time.sleep(poll)
    return value


class FakeClock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


class Peer:
    """A separate participant: publishes commands, reads joint_states and /diagnostics."""

    def __init__(self, domain_id):
        self.participant = msg.make_participant(domain_id, CONFIG)
        p = self.participant
        deep = lambda t: msg.default_qos(t, depth=1000)  # noqa: E731 (keep every sample)
        self.commands = DataWriter(p, Topic(p, "rt/joint_torque_commands", msg.Float64MultiArray),
                                   qos=msg.default_qos(msg.Float64MultiArray))
        self.joint_states = DataReader(p, Topic(p, "rt/joint_states", msg.JointState),
                                       qos=deep(msg.JointState))
        self.diagnostics = DataReader(p, Topic(p, "rt/diagnostics", msg.DiagnosticArray),
                                      qos=deep(msg.DiagnosticArray))

    def wait_matched(self):
        wait_until(lambda: msg.matched(self.commands) and msg.matched(self.joint_states),
                   "node not discovered on loopback")

    def send(self, node, data):
        """Publish one command and let the node's subscription take it (as a callback would)."""
        self.commands.write(msg.Float64MultiArray(data=list(data)))
        assert node.take_commands(timeout=TIMEOUT) == 1

    def read(self, reader, count, message_type):
        received, deadline = [], time.monotonic() + TIMEOUT
        while len(received) < count and time.monotonic() < deadline:
            received += [s for s in reader.take(N=1000) if isinstance(s, message_type)]
            time.sleep(0.001)
        assert len(received) == count
        return received


def start(domain_id, clock=None, **parameters):
    node = DdsArmSimNode(parameters, domain_id=domain_id, config=CONFIG,
                         log=logging.getLogger(f"arm_sim.test{domain_id}"),
                         wall_clock=clock or FakeClock(), start_stamp_ns=5_000_000_000)
    peer = Peer(domain_id)
    peer.wait_matched()
    return node, peer


def run_ticks(node, peer, schedule):
    for command in schedule:
        if command is not None:
            peer.send(node, command)
        node.tick()
    return peer.read(peer.joint_states, len(schedule), msg.JointState)


def test_joint_states_match_the_core_stepped_with_the_same_held_commands():
    node, peer = start(10, step_size=0.001, publish_rate=100.0)
    schedule = [(1.0, -0.5)] + [None] * 19 + [(0.0, 2.0)] + [None] * 19
    received = run_ticks(node, peer, schedule)
    assert_matches(received, expected_states(node.core.config.scene, schedule, 10))
    assert received[0].name == ["shoulder_joint", "elbow_joint"]
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in received]
    assert stamps == [5_000_000_000 + 10_000_000 * (k + 1) for k in range(40)]
    assert node.core.sim.steps == 400 and node.core.sim.time == 400 * 0.001


def test_command_plus_gravity_compensation_matches_the_core():
    node, peer = start(11, policy="command_gravity_compensation", initial_positions=[0.3, -0.2])
    schedule = [(0.5, 0.25)] + [None] * 9
    received = run_ticks(node, peer, schedule)
    assert_matches(received, expected_states(node.core.config.scene, schedule, 1))
    assert received[-1].effort != [0.5, 0.25]  # gravity torque is added to the command


@pytest.mark.parametrize("bad, why", [
    ([1.0], "has 1 values; expected 2"),
    ([1.0, 2.0, 3.0], "has 3 values; expected 2"),
    ([math.nan, 0.0], "tau1 = nan is not finite"),
    ([0.0, math.inf], "tau2 = inf is not finite"),
    ([0.0, -math.inf], "tau2 = -inf is not finite"),
    ([60.0, 0.0], "|tau1| = 60 N m exceeds torque_limit 50 N m"),
])
def test_bad_command_is_refused_with_its_reason(bad, why):
    core = node_core.ArmSimCore(node_params.resolve_parameters({}), logging.getLogger("t"))
    assert why in core.on_command(bad)
    assert core.refused_commands == 1 and core.command == (0.0, 0.0)


def test_bad_commands_over_dds_are_counted_and_the_last_good_command_holds(caplog):
    node, peer = start(12, gravity=0.0)
    good = (1.0, 0.5)
    schedule = [good, [math.nan, 0.0], [1.0], [0.0, math.inf], [99.0, 0.0], None]
    with caplog.at_level(logging.WARNING):
        received = run_ticks(node, peer, schedule)
    assert node.core.refused_commands == 4
    # The physics saw `good` throughout.
    assert_matches(received, expected_states(node.core.config.scene, [good] + [None] * 5, 1))
    for message in received:
        assert all(math.isfinite(v) for v in message.position + message.velocity + message.effort)
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1  # same second on the node's clock: one line, the rest held back
    assert "tau1 = nan is not finite" in warnings[0] and "holding [1.0, 0.5]" in warnings[0]


def test_warnings_are_rate_limited_then_report_what_was_held_back(caplog):
    clock = FakeClock()
    core = node_core.ArmSimCore(node_params.resolve_parameters({}), logging.getLogger("t"), clock)
    with caplog.at_level(logging.WARNING):
        for _ in range(5):
            core.on_command([1.0])
        clock.now += node_commands.WARN_PERIOD
        core.on_command([math.inf, 0.0])
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 2
    assert "tau1 = inf is not finite" in warnings[1] and "(4 more refused commands since" in warnings[1]
    assert core.refused_commands == 6


def test_command_timeout_drops_torque_to_zero_with_one_warning(caplog):
    node, peer = start(13, gravity=0.0, command_timeout=0.05)
    schedule = [(2.0, 0.0)] + [None] * 9
    with caplog.at_level(logging.WARNING):
        received = run_ticks(node, peer, schedule)
    efforts = [m.effort for m in received]
    # Received at t = 0; held for 5 ticks of 10 ms; at the tick that starts at t = 0.05 it drops.
    assert efforts == [[2.0, 0.0]] * 5 + [[0.0, 0.0]] * 5
    expected = expected_states(node.core.config.scene,
                               [(2.0, 0.0)] + [None] * 4 + [(0.0, 0.0)] + [None] * 4, 1)
    assert_matches(received, expected)
    timeouts = [r for r in caplog.records if "no torque command" in r.getMessage()]
    assert len(timeouts) == 1 and node.core.command_timeouts == 1


def test_zero_timeout_holds_a_command_forever():
    core = node_core.ArmSimCore(node_params.resolve_parameters({"command_timeout": 0.0}),
                                logging.getLogger("t"))
    core.on_command([1.0, 1.0])
    for _ in range(500):  # 5 s, ten times the default timeout
        data = core.tick()
    assert data.effort == [1.0, 1.0] and core.command_timeouts == 0


@pytest.mark.parametrize("parameters, name, reason", [
    ({"publish_rate": 30.0}, "publish_rate", "does not divide into steps"),
    ({"publish_rate": 0.0}, "publish_rate", "must be positive"),
    ({"step_size": -0.01}, "step_size", "must be positive"),
    ({"damping": -1.0}, "damping", "would add energy"),
    ({"gravity": math.nan}, "gravity", "not finite"),
    ({"link_masses": [1.0, 0.0]}, "link_masses", "must be positive"),
    ({"policy": "teleport"}, "policy", "unknown"),
    ({"scene": "moon"}, "scene", "unknown scene"),
    ({"torque_limit": 0}, "torque_limit", "must be positive"),
    ({"real_time_factor": -1.0}, "real_time_factor", ">= 0"),
    ({"joint_names": ["a", "a"]}, "joint_names", "distinct"),
    ({"joint_names": ["a"]}, "joint_names", "exactly two"),
    ({"initial_positions": "0,0"}, "initial_positions", "must be a list"),
    ({"rerun_spawn": "yes"}, "rerun_spawn", "true or false"),
    ({"frame_rate": 5.0}, "frame_rate", "unknown parameter"),
])
def test_bad_parameters_are_refused_with_a_reason(parameters, name, reason):
    with pytest.raises(node_params.ParameterRefused) as refused:
        DdsArmSimNode(parameters, domain_id=39, config=CONFIG)
    assert refused.value.name == name and reason in refused.value.reason


def test_runtime_parameter_refusal_changes_nothing():
    core = node_core.ArmSimCore(node_params.resolve_parameters({"damping": 0.5}), logging.getLogger("t"))
    for _ in range(7):
        core.tick()
    before = (core.config, core.sim.state, core.sim.steps)
    for change in ({"damping": -2.0}, {"publish_rate": 7.0}, {"scene": "damped_release"},
                   {"joint_names": "elbow"}):
        with pytest.raises(node_params.ParameterRefused):
            core.set_parameters(change)
    assert (core.config, core.sim.state, core.sim.steps) == before
    assert core.set_parameters({"torque_limit": 10.0}) == ["torque_limit"]
    assert core.sim.steps == 7  # a node setting: the motion goes on
    assert core.set_parameters({"damping": 1.0}) == ["damping"]
    assert core.sim.steps == 7 and core.sim.scene.damping == 1.0  # a live effect: goes on too
    assert core.set_parameters({"gravity": 1.0}) == ["gravity"]
    assert core.sim.steps == 0 and core.sim.scene.gravity == 1.0  # the arm: scene restarts


def test_integer_rates_from_the_command_line_are_taken_as_doubles():
    config = node_params.resolve_parameters({"publish_rate": 50, "step_size": 0.001})
    assert config.values["publish_rate"] == 50.0 and config.steps_per_tick == 20


def test_joint_state_bytes_decode_with_rosbags_to_the_same_values():
    node, peer = start(14, frame_id="base_link")
    peer.send(node, [0.75, -0.25])
    node.tick()
    message, = peer.read(peer.joint_states, 1, msg.JointState)
    store = get_typestore(Stores.ROS2_JAZZY)
    decoded = store.deserialize_cdr(message.serialize(), "sensor_msgs/msg/JointState")
    assert decoded.header.frame_id == "base_link" and decoded.name == message.name
    assert decoded.header.stamp.sec == 5 and decoded.header.stamp.nanosec == 10_000_000
    for field in ("position", "velocity", "effort"):
        assert list(getattr(decoded, field)) == getattr(message, field)
    assert list(decoded.effort) == [0.75, -0.25]
    assert bytes(store.serialize_cdr(decoded, "sensor_msgs/msg/JointState")) == message.serialize()


def test_ros_discovery_info_names_the_node_and_its_endpoints():
    node, peer = start(15)
    p = peer.participant
    reader = DataReader(p, Topic(p, "ros_discovery_info", msg.ParticipantEntitiesInfo),
                        qos=msg.discovery_info_qos())
    info, = peer.read(reader, 1, msg.ParticipantEntitiesInfo)  # transient-local: late joiner
    guid = lambda entity: entity.guid.bytes  # noqa: E731 (rmw's gid is the 16-byte GUID)
    assert bytes(info.gid.data) == guid(node.participant)
    entry, = info.node_entities_info_seq
    assert (entry.node_namespace, entry.node_name) == ("/", "arm_sim")
    # the topics' endpoints first; the services' follow (test_dds_services checks those)
    assert [bytes(g.data) for g in entry.reader_gid_seq][:1] == [guid(node.command_reader)]
    assert [bytes(g.data) for g in entry.writer_gid_seq][:2] == [guid(node.joint_state_writer),
                                                                 guid(node.diagnostics_writer)]
    participants = BuiltinDataReader(p, BuiltinTopicDcpsParticipant)
    deadline = time.monotonic() + TIMEOUT
    seen = {}
    while node.participant.guid not in seen and time.monotonic() < deadline:
        seen.update({s.key: s for s in participants.take(N=100)})
    assert b"enclave=/;" == [q for q in seen[node.participant.guid].qos
                             if type(q).__name__ == "Userdata"][0].data


def test_diagnostics_report_refusals_real_time_factor_residual_and_late_ticks():
    clock = FakeClock()
    node, peer = start(16, clock, publish_rate=100.0)
    first = clock.now
    for k in range(50):
        clock.now = first + 0.01 * k + (0.05 if k >= 40 else 0.0)  # tick 40 comes 50 ms late
        node.tick(clock.now)
    peer.send(node, [math.nan, 1.0])
    clock.now = first + 1.0
    node.publish_diagnostics()
    array, = peer.read(peer.diagnostics, 1, msg.DiagnosticArray)
    status, = array.status
    values = {kv.key: kv.value for kv in status.values}
    assert status.level == msg.DiagnosticStatus.WARN and status.name == "arm_sim: simulation"
    assert values["refused_commands"] == "1" and values["late_ticks"] == "1"
    # the pace counts from the first tick done (a first compile happens inside it): 0.49 s
    # simulated in the 1 s since
    assert float(values["real_time_factor"]) == pytest.approx(0.49)
    assert abs(float(values["energy_residual"])) < 1e-4  # RK4, h = 10 ms, 0.5 s of a fall
    assert node.core.sim.steps == 50  # the late tick took its steps, no more, no fewer


def test_non_finite_state_is_never_published():
    node, peer = start(17, initial_velocities=[5e153, 5e153], gravity=0.0)  # a stage's qd^2 overflows
    for _ in range(3):
        node.tick()
    received = peer.read(peer.joint_states, 3, msg.JointState)
    for message in received:
        assert all(math.isfinite(v) for v in message.position + message.velocity + message.effort)
    assert node.core.held and node.publish_diagnostics().level == interface.ERROR
    node.core.reset()
    assert not node.core.held


def test_free_running_spin_ticks_exactly_the_duration():
    node, peer = start(18, real_time_factor=0.0, step_size=0.005, publish_rate=50.0)
    lines = []
    node.spin(0.5, lines.append)
    assert node.core.sim.steps == 100 and node.core.sim.time == 100 * 0.005
    assert len(peer.read(peer.joint_states, 25, msg.JointState)) == 25
    assert "stopped at t = 0.500 s" in node.core.stop_line(False)


def spin_changing(node, duration, changes):
    """spin(duration) with `changes[tick]` (a parameter set, or "reset") applied before that
    tick, as a `ros2 param set` or a `~/reset` served between ticks would be."""
    tick, count = node.tick, [0]

    def changing_tick(now=None):
        change = changes.get(count[0])
        if change == "reset":
            node.core.reset()
        elif change is not None:
            node.core.set_parameters(change)
        count[0] += 1
        return tick(now)

    node.tick = changing_tick
    node.spin(duration)
    return count[0]


def test_duration_is_simulated_time_whatever_the_rate_becomes_and_across_resets():
    node, _ = start(19, real_time_factor=0.0, step_size=0.005, publish_rate=50.0)
    # 10 ticks of 20 ms, then 25 ms ticks (publish_rate 40): 0.2 s + 32 x 25 ms = 1.0 s
    ticks = spin_changing(node, 1.0, {10: {"publish_rate": 40.0}})
    assert ticks == 42 and node.core.stamp_ns() - node.core.start_stamp_ns == 1_000_000_000
    node, _ = start(20, real_time_factor=0.0, step_size=0.005, publish_rate=50.0)
    ticks = spin_changing(node, 0.5, {10: "reset"})   # a reset does not rewind the duration
    assert ticks == 25 and node.core.sim.time == pytest.approx(0.3)


def test_reset_restarts_the_scene_and_stamps_keep_increasing():
    core = node_core.ArmSimCore(node_params.resolve_parameters({}), logging.getLogger("t"),
                                start_stamp_ns=0)
    for _ in range(10):
        before = core.tick()
    core.reset()
    after = core.tick()
    assert after.position == expected_states(core.config.scene, [None], 1)[0][0]
    assert after.stamp_ns == before.stamp_ns + 10_000_000


# --- the command line ----------------------------------------------------------------------

def test_ros_args_resolve_as_rclcpp_does_wildcards_in_order_then_the_node_own_values(tmp_path):
    first = tmp_path / "a.yaml"
    first.write_text("/**:\n  ros__parameters:\n    damping: 0.1\n    publish_rate: 50.0\n"
                     "    gravity: 1.0\n"
                     "other_node:\n  ros__parameters:\n    damping: 9.0\n")
    second = tmp_path / "b.yaml"
    second.write_text("arm_sim:\n  ros__parameters:\n    damping: 0.2\n    use_sim_time: false\n"
                      "robot:\n  arm_sim:\n    ros__parameters:\n      frame_id: robot_base\n")
    ros = parse_ros_args(["-p", "damping:=0.7", "--params-file", str(first),
                          "--params-file", str(second), "-p", "gravity:=0",
                          "-p", "initial_positions:=[0.5, 0.0]", "-r", "__node:=arm_sim"])
    assert node_parameters(ros, "arm_sim", "/") == {
        "damping": 0.2,             # the node's own section beats every /** value and -p
        "publish_rate": 50.0,       # /** in a file
        "gravity": 0,               # a later -p beats an earlier /** file value
        "initial_positions": [0.5, 0.0]}
    assert node_parameters(ros, "arm_sim", "/robot")["frame_id"] == "robot_base"


def test_params_file_of_the_package_is_accepted():
    path = os.path.join(os.path.dirname(__file__), "..", "..", "config", "arm_sim.yaml")
    node_params.resolve_parameters(load_params_file(path))


@pytest.mark.parametrize("argv, message", [
    (["--ros-args", "-p", "publish_rate=5"], "not of the form name:=value"),
    (["--ros-args", "-p"], "needs a value"),
    (["--ros-args", "--enclave", "/x"], "not supported"),
    (["--ros-args", "--params-file", "/nonexistent.yaml"], "cannot read --params-file"),
    (["--ros-args", "-p", "publish_rate:=33.0"], "does not divide"),
    (["--duration", "nan"], "--duration"),
    (["--bogus"], "unrecognized arguments"),
])
def test_node_command_line_refusals_are_one_line_and_exit_2(argv, message, capsys):
    assert node_main(["--transport", "dds", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_transport_choice():
    assert transports.choose("dds") == "dds"
    assert transports.choose("auto") == ("rclpy" if transports.rclpy_available() else "dds")
    with pytest.raises(transports.TransportUnavailable, match="unknown transport"):
        transports.choose("carrier-pigeon")
    if not transports.rclpy_available():
        with pytest.raises(transports.TransportUnavailable, match="use --transport dds"):
            transports.choose("rclpy")


def test_arm_sim_node_process_publishes_to_a_ros_peer_on_localhost(tmp_path):
    """The README command, end to end: a separate process configured only by the ROS
    environment variables, seen by a peer on the same domain."""
    domain = 20
    peer = Peer(domain)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               CYCLONEDDS_URI=CONFIG)
    process = subprocess.Popen(
        [sys.executable, "-m", "arm_sim_ros.node.main", "--transport", "dds", "--duration", "1.5",
         "--ros-args", "-p", "publish_rate:=50", "-p", "scene:=damped_release"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        received, deadline = [], time.monotonic() + 20
        while len(received) < 5 and time.monotonic() < deadline:
            received += [s for s in peer.joint_states.take(N=100) if isinstance(s, msg.JointState)]
            time.sleep(0.01)
        out, err = process.communicate(timeout=20)
    finally:
        process.kill()
    assert process.returncode == 0, err
    assert len(received) >= 5 and received[0].name == ["shoulder_joint", "elbow_joint"]
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in received]
    assert {b - a for a, b in zip(stamps, stamps[1:])} == {20_000_000}
    assert "scene damped_release started" in err
    assert "stopped at t = 1.500 s" in err and "0 commands refused" in err


# --- telemetry hook ----------------------------------------------------------------------------

class RecorderSpy:
    """The recorder protocol (start, step after every physics step, event, finish), counted."""

    def __init__(self):
        self.calls = []

    def start(self, sim):
        self.calls.append(("start", sim.steps))

    def step(self, sim):
        self.calls.append(("step", sim.steps))

    def event(self, text, level="info"):
        self.calls.append(("event", text))
        self.levels = getattr(self, "levels", {}) | {text: level}

    def finish(self, sim):
        self.calls.append(("finish", sim.steps))


def test_recorder_sees_every_physics_step_and_the_events():
    spy = RecorderSpy()
    core = node_core.ArmSimCore(
        node_params.resolve_parameters({"step_size": 0.002, "command_timeout": 0.02}),
        logging.getLogger("t"), recorder=spy)
    core.on_command([1.0, 0.0])
    core.on_command([math.nan, 0.0])
    for _ in range(3):
        core.tick()
    core.reset()
    core.finish()
    steps = [n for kind, n in spy.calls if kind == "step"]
    assert steps == list(range(1, 16))          # 3 ticks x 5 steps, each seen once, in order
    events = [text for kind, text in spy.calls if kind == "event"]
    assert events[0].startswith("scene release started")
    assert any("refused command: tau1 = nan" in e for e in events)
    assert any("command timeout" in e for e in events)
    # events carry the level the node logged them at: refusals and timeouts are warnings
    assert {spy.levels[e] for e in events if "refused" in e or "timeout" in e} == {"warn"}
    assert events[-1] == "reset to the scene's initial state"
    assert spy.calls[-1] == ("finish", 0) and [c for c in spy.calls if c[0] == "start"] == [
        ("start", 0), ("start", 0)]


def test_rerun_path_parameter_writes_a_recording_of_the_node(tmp_path):
    pytest.importorskip("arm_sim_ros.recording.rrd.telemetry")
    rr = pytest.importorskip("rerun")
    path = tmp_path / "node.rrd"
    core = node_core.ArmSimCore(node_params.resolve_parameters({"rerun_path": str(path)}),
                                logging.getLogger("t"))
    core.on_command([1.0])
    for _ in range(20):
        core.tick()
    core.finish()
    reader = rr.chunk.RrdReader(str(path))
    recording, = reader.recordings()
    entities = {chunk.entity_path.lstrip("/") for chunk in reader.stream(store=recording)}
    assert {"energy/total", "energy/balance_residual", "events"} <= entities


# --- arm-sim send-torque ------------------------------------------------------------------------

def test_send_torque_publisher_drives_the_node():
    from arm_sim_ros.tools.wire.send_torque import TorquePublisher

    node, _ = start(30, gravity=0.0)
    publisher = TorquePublisher(domain_id=30, config=CONFIG)
    assert publisher.wait_for_subscriber(TIMEOUT)
    publisher.send([1.5, -0.5])
    assert node.take_commands(timeout=TIMEOUT) == 1
    assert node.tick().effort == [1.5, -0.5]


def test_send_torque_command_line(monkeypatch, capsys):
    from arm_sim_ros.tools.cli import main as cli_main

    monkeypatch.setenv("ROS_DOMAIN_ID", "31")      # nobody listens on this domain
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("CYCLONEDDS_URI", CONFIG)
    assert cli_main(["send-torque", "1", "0", "--once", "--wait", "0.2"]) == 1
    assert "no subscriber on joint_torque_commands" in capsys.readouterr().err
    assert cli_main(["send-torque", "1", "0", "--rate", "0"]) == 2
    assert "--rate 0.0 must be a positive number" in capsys.readouterr().err
    # refused before joining the network: no wait for discovery (issue 39)
    for torques in (["nan", "0"], ["1", "inf"]):
        assert cli_main(["send-torque", *torques, "--wait", "30"]) == 2
        assert "is not a torque (finite N m)" in capsys.readouterr().err


def test_send_torque_repeats_at_its_rate_acknowledged_once():
    """Each message waited for its acknowledgements: --rate 100 --duration 3 ran 32 s, ~10 Hz
    whatever the rate. Written on schedule, only the last is waited for."""
    from arm_sim_ros.tools.wire.send_torque import TorquePublisher

    node, _ = start(32, gravity=0.0)
    publisher = TorquePublisher(domain_id=32, config=CONFIG)
    assert publisher.wait_for_subscriber(TIMEOUT)
    waits, written, writer = [], [], publisher.writer
    publisher.writer = types.SimpleNamespace(
        write=lambda sample: written.append(sample) or writer.write(sample),
        wait_for_acks=lambda timeout: waits.append(timeout) or writer.wait_for_acks(timeout))
    publisher.repeat([0.5, -0.5], 200.0, 0.25)
    assert len(written) == 50 and len(waits) == 1           # 0.25 s at 200 Hz
    assert node.take_commands(timeout=TIMEOUT) >= 1 and node.tick().effort == [0.5, -0.5]


def test_the_tick_schedule_makes_up_a_short_lag_and_restarts_after_a_long_one():
    from arm_sim_ros.node.schedule import CATCH_UP, TickSchedule
    period = 0.002                                  # 100 Hz at real_time_factor 5
    schedule = TickSchedule(0.0)
    schedule.ticked(0.0, period)
    assert schedule.wait(0.001) > 0                 # early: wait for it
    late = 0.0105                                   # a callback 8.5 ms late (Python's cost)
    due = 0
    while schedule.wait(late) <= 0:                 # ticks back to back until on schedule
        schedule.ticked(late, period)
        due += 1
    assert due == 5 and 0 < schedule.wait(late) <= period
    schedule.ticked(1.0, period)                    # a one-second stall: no burst after it
    assert schedule.next_tick == 1.0 and CATCH_UP < 1.0


class Spinning:
    """A node spinning in real time in a thread (its /diagnostics once a wall second) until
    `stop()`."""

    def __init__(self, domain_id, **parameters):
        import threading

        self.node = DdsArmSimNode(parameters, domain_id=domain_id, config=CONFIG,
                                  log=logging.getLogger(f"arm_sim.test{domain_id}"),
                                  wall_clock=time.monotonic, start_stamp_ns=0)
        self.done = False
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self):
        try:
            self.node.spin(stopped=lambda: self.done)
        except KeyboardInterrupt:
            pass

    def stop(self):
        self.done = True
        self.thread.join(TIMEOUT)


def sender_lines(err: str) -> list:
    """The sender's lines on stderr, without the node's log lines (a test before may have
    sent the node's logging there: node_main configures it)."""
    return [line for line in err.splitlines() if not line.startswith("[")]


@pytest.mark.parametrize("argv, said", [
    (["100", "0", "--duration", "1"],
     "of the 10 commands sent: |tau1| = 100 N m exceeds torque_limit 50 N m (its /diagnostics "
     "refused_commands rose from 0 to "),
    (["0", "-60", "--once"],
     "the node refused 1 of the 1 commands sent: |tau2| = 60 N m exceeds torque_limit 50 N m "
     "(its /diagnostics refused_commands rose from 0 to 1)"),
    (["1", "0", "--duration", "0.5", "@policy=zero"],
     "the node's policy 'zero' ignores torque commands (its /diagnostics say so): set its "
     "policy to command")])
def test_send_torque_says_when_the_node_refuses_or_ignores_its_commands(monkeypatch, capsys,
                                                                        argv, said):
    """Issue 47: against a node with torque_limit 50, `send-torque 100 0` printed "sending",
    exit 0, while the node refused every command. The node's /diagnostics say how many it
    refused and why (last_refusal), and which policy it follows: the sender reads them."""
    from arm_sim_ros.tools.cli import main as cli_main

    domain = 33 + len(argv)
    parameters = dict(a[1:].split("=") for a in argv if a.startswith("@"))
    spinning = Spinning(domain, **({"policy": "command"} | parameters))
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("CYCLONEDDS_URI", CONFIG)
    try:
        code = cli_main(["send-torque", *[a for a in argv if not a.startswith("@")], "--wait",
                         "10"])
    finally:
        spinning.stop()
    out, err = capsys.readouterr()
    err = sender_lines(err)
    assert code == 1 and len(err) == 1 and "Traceback" not in err[0], (out, err)
    assert err[0].startswith("arm-sim: error: the node") and said in err[0], err


def test_send_torque_within_the_limits_is_taken_and_exits_0(monkeypatch, capsys):
    from arm_sim_ros.tools.cli import main as cli_main

    spinning = Spinning(40, policy="command")
    monkeypatch.setenv("ROS_DOMAIN_ID", "40")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("CYCLONEDDS_URI", CONFIG)
    try:
        code = cli_main(["send-torque", "10", "-5", "--duration", "0.5", "--wait", "10"])
    finally:
        spinning.stop()
    out, err = capsys.readouterr()
    assert code == 0 and sender_lines(err) == [] and out.startswith("sending [10.0, -5.0] N m")
    core = spinning.node.core            # it waited for the node to take all it sent
    assert core.received_commands == 5 and core.refused_commands == 0
