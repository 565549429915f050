"""rosbag2 recordings: `arm-sim run --bag` against the core, `arm-sim record` against what a
participant published on the ROS 2 wire, and an interrupted recorder's bag.

DDS here is loopback only (interface 127.0.0.1, no multicast, peer 127.0.0.1), on domain
ids 40-59 that no other test module uses.
"""
import logging
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import yaml
from rosbags.rosbag2 import Reader

from arm_sim_ros.tools import cli
from arm_sim_ros.node import core as node_core
from arm_sim_ros.node.params import parameters as node_params
from arm_sim_ros.interface import NODE_TOPICS
from arm_sim_ros.recording.bags.bag import TYPESTORE, BagWriter, joint_state
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator

INFINITE = {"sec": 9223372036, "nsec": 854775807}
# Jazzy's metadata for a publisher with the ROS default profile, as `ros2 bag record` writes it.
JAZZY_DEFAULT_OFFER = {"history": "unknown", "depth": 0, "reliability": "reliable",
                       "durability": "volatile", "deadline": INFINITE, "lifespan": INFINITE,
                       "liveliness": "automatic", "liveliness_lease_duration": INFINITE,
                       "avoid_ros_namespace_conventions": False}


def read_bag(path):
    """{topic: [(bag time ns, message, raw bytes)]} and {topic: connection}."""
    with Reader(path) as reader:
        connections = {c.topic: c for c in reader.connections}
        messages = {topic: [] for topic in connections}
        for connection, timestamp, raw in reader.messages():
            message = TYPESTORE.deserialize_cdr(raw, connection.msgtype)
            messages[connection.topic].append((timestamp, message, bytes(raw)))
    return messages, connections


def run_bag(capsys, tmp_path, *argv, exit_code=0):
    path = tmp_path / "bag"
    code = cli.main(["run", *argv, "--bag", str(path)])
    _, err = capsys.readouterr()
    assert code == exit_code, err
    return path


def core_samples(scene, every):
    """The core stepped alone: a sample at t = 0 and after every `every` steps."""
    sim = Simulator(scene)
    samples = [(sim.steps, sim.sample())]
    for _ in range(scene.steps_for(scene.duration)):
        sim.step()
        if sim.steps % every == 0:
            samples.append((sim.steps, sim.sample()))
    return samples


# --- arm-sim run --bag ---------------------------------------------------------------------

def test_run_bag_is_a_jazzy_mcap_bag_with_definitions_and_offered_qos(capsys, tmp_path):
    path = run_bag(capsys, tmp_path, "--scene", "shoulder_torque_no_gravity")
    assert sorted(p.name for p in path.iterdir()) == ["bag.mcap", "metadata.yaml"]
    assert (path / "bag.mcap").read_bytes()[:8] == b"\x89MCAP0\r\n"
    info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["ros_distro"] == "jazzy"              # what `ros2 bag info` shows as ROS Distro
    start = info["starting_time"]["nanoseconds_since_epoch"]
    assert abs(start - time.time_ns()) < 3600 * 10**9  # started now, not on 1 Jan 1970
    assert info["message_count"] == 51 + 51 + 1
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    assert {name: t["topic_metadata"]["type"] for name, t in topics.items()} == NODE_TOPICS
    for name, t in topics.items():
        meta = t["topic_metadata"]
        assert meta["serialization_format"] == "cdr"
        assert meta["offered_qos_profiles"] == [JAZZY_DEFAULT_OFFER]
        assert meta["type_description_hash"] == TYPESTORE.hash_rihs01(meta["type"])
    _, connections = read_bag(path)
    for topic, connection in connections.items():
        # The full definition (with nested types) rides in the MCAP schema record.
        assert connection.msgdef.data == TYPESTORE.generate_msgdef(connection.msgtype, ros_version=2)[0]
        assert connection.msgdef.data.count("MSG: ") >= 1


@pytest.mark.parametrize("scene_name, rate, every", [
    ("release", 100.0, 1),
    ("damped_release", 50.0, 2),
    ("shoulder_torque_no_gravity", 25.0, 4),
])
def test_run_bag_joint_states_equal_the_core_at_the_publish_rate(capsys, tmp_path, scene_name,
                                                                  rate, every):
    before = time.time_ns()
    path = run_bag(capsys, tmp_path, "--scene", scene_name, "--publish-rate", str(rate))
    messages, _ = read_bag(path)
    origin = messages["/joint_states"][0][0]      # bag time of t = 0: the wall clock at start
    assert before <= origin <= time.time_ns()
    expected = core_samples(load_scene(scene_name), every)
    recorded = messages["/joint_states"]
    assert len(recorded) == len(expected)
    for (steps, sample), (timestamp, message, _) in zip(expected, recorded):
        t_ns = round(steps * 0.01 * 1e9)
        assert timestamp == origin + t_ns  # bag time: wall clock at start + simulated time
        assert message.header.stamp.sec * 10**9 + message.header.stamp.nanosec == t_ns
        assert list(message.name) == ["shoulder_joint", "elbow_joint"]
        assert message.position.tolist() == list(sample.q)
        assert message.velocity.tolist() == list(sample.qd)
        assert message.effort.tolist() == list(sample.tau)
    assert [t for t, _, _ in recorded] == sorted({t for t, _, _ in recorded})


def test_run_bag_records_the_constant_command_alongside_each_joint_state(capsys, tmp_path):
    path = run_bag(capsys, tmp_path, "--scene", "shoulder_torque_no_gravity")
    messages, _ = read_bag(path)
    commands = messages["/joint_torque_commands"]
    assert [t for t, _, _ in commands] == [t for t, _, _ in messages["/joint_states"]]
    for _, message, _ in commands:
        assert message.data.tolist() == [1.0, 0.0]
        assert len(message.layout.dim) == 0 and message.layout.data_offset == 0


def test_run_bag_without_commands_has_no_command_topic(capsys, tmp_path):
    messages, _ = read_bag(run_bag(capsys, tmp_path, "--scene", "release"))
    assert set(messages) == {"/joint_states", "/diagnostics"}


def test_run_bag_diagnostics_every_simulated_second_and_at_the_end(capsys, tmp_path):
    path = run_bag(capsys, tmp_path, "--scene", "damped_release", "--duration", "2.5")
    messages, _ = read_bag(path)
    diagnostics = messages["/diagnostics"]
    origin = messages["/joint_states"][0][0]
    assert [t - origin for t, _, _ in diagnostics] == [1_000_000_000, 2_000_000_000, 2_500_000_000]
    sim = Simulator(load_scene("damped_release"))
    node = node_core.ArmSimCore(node_params.resolve_parameters({}), logging.getLogger("keys"))
    node_keys = [key for key, _ in node.diagnostics().values]
    for timestamp, message, _ in diagnostics:
        sim.run((timestamp - origin) / 1e9 - sim.time)
        (status,) = message.status
        values = {kv.key: kv.value for kv in status.values}
        assert status.level == 0 and status.name == "arm_sim: simulation"
        assert values["sim_time"] == f"{sim.time:.6f}"
        assert values["energy_residual"] == f"{sim.residual():.3e}"
        assert values["refused_commands"] == "0"
        assert float(values["real_time_factor"]) > 0
        assert list(values) == node_keys   # the node's diagnostics, key for key


def test_run_bag_records_only_finite_values_and_reports_a_refused_step(capsys, tmp_path):
    path = run_bag(capsys, tmp_path, "--set", "initial_velocities=5e153,5e153", "--duration", "1",
                   exit_code=1)                     # a run that faulted says so
    messages, _ = read_bag(path)
    for _, message, _ in messages["/joint_states"]:
        assert np.isfinite([*message.position, *message.velocity, *message.effort]).all()
    ((_, diagnostics, _),) = messages["/diagnostics"]
    (status,) = diagnostics.status
    assert status.level == 2 and "holding the last finite state" in status.message
    assert {kv.key: kv.value for kv in status.values}["energy_residual"] == "held"


@pytest.mark.parametrize("argv, reason", [
    (["--publish-rate", "30"], "does not divide"),
    (["--publish-rate", "0"], "positive"),
    (["--publish-rate", "nan"], "positive"),
    (["--step", "0.003", "--duration", "0.006"], "does not divide"),
])
def test_run_bag_refuses_a_rate_that_does_not_divide_the_step(capsys, tmp_path, argv, reason):
    code = cli.main(["run", "--bag", str(tmp_path / "bag"), *argv])
    _, err = capsys.readouterr()
    assert code == 2 and reason in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "bag").exists()


def test_run_bag_never_overwrites_a_recording(capsys, tmp_path):
    (tmp_path / "bag").mkdir()
    (tmp_path / "bag" / "keep").write_text("mine")
    code = cli.main(["run", "--bag", str(tmp_path / "bag")])
    assert code == 2 and "exists already" in capsys.readouterr().err
    assert [p.name for p in (tmp_path / "bag").iterdir()] == ["keep"]


def test_bag_writer_serialises_exactly_what_was_given(tmp_path):
    message = joint_state(1_234_567_890_123, [1.5, -2.0], [0.25, 3.0], [0.0, -1.0], frame_id="base")
    with BagWriter(tmp_path / "bag") as writer:
        writer.add_topic("/joint_states", NODE_TOPICS["/joint_states"])
        writer.write("/joint_states", 42, message)
    messages, _ = read_bag(tmp_path / "bag")
    ((timestamp, read, raw),) = messages["/joint_states"]
    assert timestamp == 42 and raw == bytes(TYPESTORE.serialize_cdr(message, message.__msgtype__))
    assert (read.header.stamp.sec, read.header.stamp.nanosec) == (1234, 567_890_123)
    assert read.header.frame_id == "base" and read.effort.tolist() == [0.0, -1.0]


# --- arm-sim record on the dds transport ----------------------------------------------------

wire = pytest.importorskip("arm_sim_ros.node.wire.messages")
# Loopback only, and tagged with this process: a participant only discovers peers with the
# same discovery tag, so a second run of this suite on the same domain ids cannot interfere.
ISOLATED = wire.LOOPBACK_CONFIG.replace(
    "<Discovery>", f"<Discovery><Tag>arm_sim_test_bag_{os.getpid()}</Tag>", 1)


def writer_for(participant, topic, message_type, qos=None):
    """A reliable writer that keeps every sample until acknowledged: a keep-last writer may
    replace an unacknowledged sample in a burst, a loss the recorder could never see. A write
    waits for room as long as a busy machine needs (the default 100 ms made write() time out
    once in 7 suite runs while the recorder's process was starved)."""
    from cyclonedds.pub import DataWriter
    from cyclonedds.qos import Policy, Qos
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    qos = (qos or wire.default_qos(message_type)) + Qos(
        Policy.History.KeepAll, Policy.Reliability.Reliable(max_blocking_time=duration(seconds=60)))
    return DataWriter(participant, Topic(participant, wire.ros_topic(topic), message_type), qos=qos)


def wait_matched(writers, readers=1, timeout=20.0):
    deadline = time.monotonic() + timeout
    while not all(wire.matched(w) >= readers for w in writers):
        assert time.monotonic() < deadline, "the recorder never subscribed"
        time.sleep(0.01)


def joint_states(count, offset=0.0):
    return [wire.JointState(header=wire.Header(stamp=wire.Time(100 + k, 1000 * k), frame_id="f"),
                            name=["shoulder_joint", "elbow_joint"],
                            position=[0.1 * k + offset, -0.2 * k], velocity=[1.0 / (k + 1), 2.0],
                            effort=[float(k), 0.5]) for k in range(count)]


def start_recording(path, topics, participant):
    """Readers made on this thread (cyclonedds must not build a topic type on two threads at
    once), the recording loop on another; returns a function that stops it like Ctrl-C
    and returns the counts."""
    from arm_sim_ros.tools.wire.record import TopicRecorder
    from arm_sim_ros.tools.signals import StopOnSignals

    writer = BagWriter(path)
    recorder = TopicRecorder(participant, topics, writer)
    stop = StopOnSignals()
    thread = threading.Thread(target=recorder.run, args=(stop,))
    thread.start()

    def finish():
        stop.requested = True
        thread.join(10)
        writer.close()
        return dict(writer.counts)

    return finish


def assert_recorded(messages, topic, published):
    recorded = messages[topic]
    assert [raw for _, _, raw in recorded] == [m.serialize() for m in published]
    assert [t for t, _, _ in recorded] == sorted(t for t, _, _ in recorded)


def test_record_writes_exactly_what_a_participant_published(tmp_path):
    from cyclonedds.qos import Policy, Qos

    domain = 47
    publisher = wire.make_participant(domain, ISOLATED)
    recorder = wire.make_participant(domain, ISOLATED)
    topics = dict(NODE_TOPICS) | {"/target": "sensor_msgs/msg/JointState"}
    finish = start_recording(tmp_path / "bag", topics, recorder)
    try:
        target_qos = wire.default_qos(wire.JointState) + Qos(
            Policy.Durability.TransientLocal, Policy.Deadline(1_500_000_000))
        writers = {"/joint_states": writer_for(publisher, "/joint_states", wire.JointState),
                   "/joint_torque_commands": writer_for(publisher, "/joint_torque_commands",
                                                        wire.Float64MultiArray),
                   "/diagnostics": writer_for(publisher, "/diagnostics", wire.DiagnosticArray),
                   "/target": writer_for(publisher, "/target", wire.JointState, target_qos)}
        unrecorded = writer_for(publisher, "/elsewhere", wire.JointState)
        wait_matched(writers.values())
        published = {
            "/joint_states": joint_states(30),
            "/joint_torque_commands": [wire.Float64MultiArray(data=[0.5 * k, -1.0]) for k in range(7)],
            "/diagnostics": [wire.DiagnosticArray(
                header=wire.Header(stamp=wire.Time(5, 0)),
                status=[wire.DiagnosticStatus(level=1, name="arm_sim: simulation", message="m",
                                              hardware_id="arm_sim",
                                              values=[wire.KeyValue("sim_time", "1.000000")])])],
            "/target": joint_states(3, offset=10.0),
        }
        for topic, messages in published.items():
            for message in messages:
                writers[topic].write(message)
        unrecorded.write(joint_states(1)[0])
        for w in writers.values():
            assert w.wait_for_acks(5_000_000_000)
    finally:
        result = finish()
    assert result == {topic: len(m) for topic, m in published.items()}
    messages, connections = read_bag(tmp_path / "bag")
    assert set(messages) == set(published)
    for topic, sent in published.items():
        assert_recorded(messages, topic, sent)
        assert connections[topic].msgtype == topics[topic]
    _, js, _ = messages["/joint_states"][4]
    assert js.position.tolist() == [0.4, -0.8] and js.header.stamp.nanosec == 4000
    # The offers written are the publishers' own, as discovery reported them.
    info = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())
    offers = {t["topic_metadata"]["name"]: t["topic_metadata"]["offered_qos_profiles"]
              for t in info["rosbag2_bagfile_information"]["topics_with_message_count"]}
    assert offers["/joint_states"] == [JAZZY_DEFAULT_OFFER]
    assert offers["/target"] == [JAZZY_DEFAULT_OFFER | {
        "durability": "transient_local", "deadline": {"sec": 1, "nsec": 500_000_000}}]


def test_record_of_the_live_node_equals_the_core_with_the_same_commands(tmp_path):
    from arm_sim_ros.node.transports.dds import DdsArmSimNode

    domain = 50
    recorder = wire.make_participant(domain, ISOLATED)
    finish = start_recording(tmp_path / "bag", dict(NODE_TOPICS), recorder)
    try:
        node = DdsArmSimNode({"scene": "release", "step_size": 0.001, "publish_rate": 100.0},
                             domain_id=domain, config=ISOLATED,
                             wall_clock=lambda: 100.0, start_stamp_ns=7_000_000_000)
        peer = wire.make_participant(domain, ISOLATED)
        commands = writer_for(peer, "/joint_torque_commands", wire.Float64MultiArray)
        wait_matched([node.joint_state_writer, node.diagnostics_writer])
        wait_matched([commands], readers=2)  # the node and the recorder
        held = {0: [1.0, 0.5], 8: [-0.5, 0.0]}
        for tick in range(15):
            if tick in held:
                commands.write(wire.Float64MultiArray(data=held[tick]))
                assert node.take_commands(timeout=5.0) == 1
            node.tick()
        node.publish_diagnostics()
        for w in (node.joint_state_writer, node.diagnostics_writer, commands):
            assert w.wait_for_acks(5_000_000_000)
    finally:
        result = finish()
    assert result == {"/joint_states": 15, "/joint_torque_commands": 2, "/diagnostics": 1}
    messages, _ = read_bag(tmp_path / "bag")
    sim = Simulator(load_scene("release").replace(policy="command", step_size=0.001))
    for tick, (_, message, _) in enumerate(messages["/joint_states"]):
        if tick in held:
            sim.set_command(*held[tick])
        for _ in range(10):
            sim.step()
        s = sim.sample()
        stamp = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
        assert stamp == 7_000_000_000 + (tick + 1) * 10_000_000
        assert message.position.tolist() == list(s.q) and message.velocity.tolist() == list(s.qd)
        assert message.effort.tolist() == list(s.tau)
    assert [m.data.tolist() for _, m, _ in messages["/joint_torque_commands"]] == list(held.values())
    info = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())
    for topic in info["rosbag2_bagfile_information"]["topics_with_message_count"]:
        assert topic["topic_metadata"]["offered_qos_profiles"] == [JAZZY_DEFAULT_OFFER]


RECORD_MAIN = "import sys; from arm_sim_ros.tools.cli import main; sys.exit(main(sys.argv[1:]))"


@pytest.mark.parametrize("domain, signum", [(48, signal.SIGINT), (49, signal.SIGTERM)])
def test_an_interrupted_recorder_leaves_a_readable_bag_with_everything_received(tmp_path, domain,
                                                                                signum):
    env = os.environ | {"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                        "CYCLONEDDS_URI": ISOLATED, "ROS_STATIC_PEERS": ""}
    path = tmp_path / "bag"
    process = subprocess.Popen([sys.executable, "-c", RECORD_MAIN, "record", str(path)], env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        publisher = wire.make_participant(domain, ISOLATED)
        writer = writer_for(publisher, "/joint_states", wire.JointState)
        wait_matched([writer])
        sent = joint_states(600)  # more than one take() batch
        for message in sent:
            writer.write(message)
        assert writer.wait_for_acks(60_000_000_000)  # in the recorder's reader, not yet on disk
        process.send_signal(signum)
        out, err = process.communicate(timeout=20)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 0, err
    assert "/joint_states 600" in out
    messages, _ = read_bag(path)
    assert_recorded(messages, "/joint_states", sent)
    assert np.array_equal(messages["/joint_states"][-1][1].position, np.array(sent[-1].position))


def test_record_refuses_before_joining_the_network(capsys, tmp_path):
    (tmp_path / "bag").mkdir()
    for argv, reason in ((["record", str(tmp_path / "bag")], "exists already"),
                         (["record", "--topics", "/x:Twist", str(tmp_path / "new")], "NAME:TYPE"),
                         (["record", "--duration", "-1", str(tmp_path / "new")], "positive")):
        assert cli.main(argv) == 2
        assert reason in capsys.readouterr().err
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize("domain, clock_origin", [(52, "zero"), (53, "wall")])
def test_a_node_recording_and_an_arm_sim_record_bag_of_the_same_run_line_up(tmp_path, domain,
                                                                            clock_origin):
    """The node writes a Rerun recording while `arm-sim record` (its TopicRecorder) writes a
    bag of the same run: every JointState in the bag is a row of the recording at the same
    ros_time (its header stamp) with the same angles, so both open on one clock."""
    from recording.test_telemetry import read_back
    from arm_sim_ros.node.transports.dds import DdsArmSimNode

    rrd = tmp_path / "node.rrd"
    recorder = wire.make_participant(domain, ISOLATED)
    finish = start_recording(tmp_path / "bag", {"/joint_states": NODE_TOPICS["/joint_states"]},
                             recorder)
    try:
        started = time.time_ns()
        node = DdsArmSimNode({"scene": "damped_release", "publish_rate": 50.0,
                              "rerun_path": str(rrd), "clock_origin": clock_origin},
                             domain_id=domain, config=ISOLATED, wall_clock=lambda: 100.0)
        wait_matched([node.joint_state_writer])
        for _ in range(30):
            node.tick()
        assert node.joint_state_writer.wait_for_acks(5_000_000_000)
        node.close()
    finally:
        counts = finish()
    assert counts == {"/joint_states": 30}
    messages, _ = read_bag(tmp_path / "bag")
    first = messages["/joint_states"][0][1].header.stamp
    origin = first.sec * 10**9 + first.nanosec - 20_000_000      # the first tick is 20 ms in
    assert origin == 0 if clock_origin == "zero" else started <= origin <= time.time_ns()
    angles = read_back(rrd)["joints/angle"]
    recorded = dict(zip(angles["ros_time"], angles["Scalars:scalars"]))
    for _, message, _ in messages["/joint_states"]:
        stamp = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
        assert recorded[stamp] == message.position.tolist()     # one clock, to the nanosecond
