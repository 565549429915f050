"""No answer is silent or misleading: each case a new user met on the second try gets one
clear line and a non-zero exit (issue 36, item 5), and a wrong message type on one of the
node's topics is refused before anything joins the network."""
import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from arm_sim_ros.interface import KNOWN_TOPICS, wrong_type
from arm_sim_ros.node import main as node_main
from arm_sim_ros.node.params.parameters import ParameterRefused, resolve_parameters
from arm_sim_ros.tools import cli
from arm_sim_ros.tools.wire.record import DEFAULT_TOPICS

wire = pytest.importorskip("arm_sim_ros.node.wire.messages")
CONFIG = wire.loopback_config(f"arm_sim_test_no_silent_answers_{os.getpid()}")
CLI = "import sys; from arm_sim_ros.tools.cli import main; sys.exit(main(sys.argv[1:]))"


def one_line(capsys, code, expected_code=2) -> str:
    out, err = capsys.readouterr()
    assert code == expected_code and err.count("\n") == 1 and "Traceback" not in err, (out, err)
    return err


def dds_env(monkeypatch, domain: int) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("CYCLONEDDS_URI", CONFIG)


# --- a wrong message type on a known topic ----------------------------------------------

def test_each_of_the_nodes_topics_carries_one_type_and_no_other():
    assert KNOWN_TOPICS["/joint_states"] == "sensor_msgs/msg/JointState"
    assert KNOWN_TOPICS["/joint_torque_commands"] == "std_msgs/msg/Float64MultiArray"
    assert wrong_type("joint_states", "std_msgs/msg/Float64MultiArray") == (
        "/joint_states carries sensor_msgs/msg/JointState, not std_msgs/msg/Float64MultiArray")
    assert wrong_type("/joint_states", "sensor_msgs/msg/JointState") is None
    assert wrong_type("/elsewhere", "std_msgs/msg/Float64MultiArray") is None


def test_record_refuses_a_known_topic_named_with_another_type(capsys, tmp_path):
    """It recorded no JointState and exited 0."""
    bag = tmp_path / "bag"
    err = one_line(capsys, cli.main(["record", str(bag), "--topics",
                                     "/joint_states:Float64MultiArray"]))
    assert err == ("arm-sim: error: --topics '/joint_states:Float64MultiArray': /joint_states "
                   "carries sensor_msgs/msg/JointState, not std_msgs/msg/Float64MultiArray (the "
                   "arm_sim node's topic); it is recorded by default\n")
    err = one_line(capsys, cli.main(["record", str(bag), "--topics",
                                     "joint_commands:Float64MultiArray"]))
    assert err.endswith("; --topics /joint_commands:JointState\n")
    assert not bag.exists()


def test_send_torque_refuses_a_known_topic_of_another_type(capsys):
    """It said `no subscriber ... is arm_sim_node running?` while the node ran."""
    err = one_line(capsys, cli.main(["send-torque", "1", "0", "--topic", "joint_states"]))
    assert err == ("arm-sim: error: --topic joint_states: /joint_states carries "
                   "sensor_msgs/msg/JointState, not std_msgs/msg/Float64MultiArray (the arm_sim "
                   "node's topic); send-torque publishes std_msgs/msg/Float64MultiArray torques: "
                   "leave --topic out for joint_torque_commands\n")


def test_send_torque_names_the_type_it_finds_on_another_topic(monkeypatch, capsys):
    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic

    dds_env(monkeypatch, 211)
    other = wire.make_participant(211, CONFIG)
    theirs = DataWriter(other, Topic(other, wire.ros_topic("/their_states"), wire.JointState),
                        qos=wire.default_qos(wire.JointState))
    code = cli.main(["send-torque", "1", "0", "--once", "--topic", "their_states",
                     "--wait", "1"])
    err = one_line(capsys, code, expected_code=1)
    assert err == ("send-torque: no subscriber on their_states after 1 s; their_states carries "
                   "sensor_msgs/msg/JointState on the wire, not std_msgs/msg/Float64MultiArray\n")
    del theirs


# --- arm-sim record: nothing received, and a recorder started before its node -------------

def test_a_recording_that_received_nothing_says_so_exits_1_and_leaves_no_bag(tmp_path):
    """The live-record example wrote `no messages` and exit 0 when the node was gone."""
    env = os.environ | {"ROS_DOMAIN_ID": "212", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                        "CYCLONEDDS_URI": CONFIG, "ROS_STATIC_PEERS": ""}
    bag = tmp_path / "bag"
    process = subprocess.Popen([sys.executable, "-c", CLI, "record", str(bag), "--duration", "1"],
                               env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not bag.exists():               # recording (and waiting for a first message)
            assert time.monotonic() < deadline and process.poll() is None, process.stderr.read()
            time.sleep(0.05)
        time.sleep(1.5)                       # past --duration: it waits on, nothing came
        assert process.poll() is None
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 1, err
    assert out == ""
    assert err.splitlines()[-1] == (
        f"record: no message arrived on {', '.join(DEFAULT_TOPICS)}; no "   # main's truth topic too
        "bag written. Is the node running (and publishing while this records), with the same "
        "ROS_DOMAIN_ID and ROS_AUTOMATIC_DISCOVERY_RANGE?")
    assert not bag.exists()


def test_record_duration_counts_from_the_first_message(tmp_path):
    """A recorder started before its node records --duration seconds of what it publishes."""
    from recording.test_bag import joint_states, read_bag, wait_matched, writer_for
    from arm_sim_ros.recording.bags.bag import BagWriter
    from arm_sim_ros.tools.signals import StopOnSignals
    from arm_sim_ros.tools.wire.record import TopicRecorder

    recorder_side = wire.make_participant(213, CONFIG)
    writer = BagWriter(tmp_path / "bag")
    recorder = TopicRecorder(recorder_side, {"/joint_states": "sensor_msgs/msg/JointState"},
                             writer)
    thread = threading.Thread(target=recorder.run, args=(StopOnSignals(), 0.5))
    thread.start()
    try:
        time.sleep(1.0)                       # longer than --duration: nothing yet, it waits
        assert thread.is_alive()
        publisher = writer_for(wire.make_participant(213, CONFIG), "/joint_states",
                               wire.JointState)
        wait_matched([publisher])
        for message in joint_states(5):
            publisher.write(message)
        assert publisher.wait_for_acks(30_000_000_000)
        thread.join(30)
        assert not thread.is_alive()          # 0.5 s after the first message
    finally:
        writer.close()
    messages, _ = read_bag(tmp_path / "bag")
    assert len(messages["/joint_states"]) == 5


# --- inspect, --set and the node's command line -------------------------------------------

def test_inspect_of_a_bag_directory_says_it_is_a_bag(capsys, tmp_path):
    """It said `no such file`."""
    bag = tmp_path / "damped"
    assert cli.main(["run", "--duration", "0.05", "--bag", str(bag)]) == 0
    capsys.readouterr()
    err = one_line(capsys, cli.main(["inspect", str(bag)]))
    assert err.startswith(f"arm-sim: error: {bag} is a bag (a rosbag2 directory); inspect reads "
                          f"Rerun recordings (.rrd): `ros2 bag info {bag}`")
    err = one_line(capsys, cli.main(["inspect", str(tmp_path)]))
    assert err == f"arm-sim: error: {tmp_path} is a directory; inspect reads a Rerun recording " \
                  "file (.rrd)\n"
    err = one_line(capsys, cli.main(["inspect", str(tmp_path / "none.rrd")]))
    assert err == f"arm-sim: error: {tmp_path / 'none.rrd'}: no such file\n"


@pytest.mark.parametrize("assignment, hint", [
    ("dampng=0.3", "unknown scene key 'dampng'; did you mean 'damping'? known keys: name, "),
    ("stiffness=20,5", "unknown scene key 'stiffness'; did you mean 'springs.stiffness'? "),
    ("springs.stifness=20,5", "springs.stifness is not a key of springs; did you mean "
                              "'springs.stiffness'? its keys: stiffness, rest_positions"),
], ids=["scene key", "an effect's key without its effect", "an effect's key"])
def test_a_misspelt_set_key_gets_did_you_mean(capsys, assignment, hint):
    """Scene names had it; --set keys did not."""
    err = one_line(capsys, cli.main(["run", "--set", assignment, "--duration", "0.1"]))
    assert err.startswith(f"arm-sim: error: {hint}")


def test_a_misspelt_key_in_a_scene_file_or_a_node_parameter_gets_did_you_mean(tmp_path, capsys):
    scene = tmp_path / "typo.yaml"
    scene.write_text("dampng: 0.3\nsprings: {stifness: [1.0, 1.0]}\n")
    err = one_line(capsys, cli.main(["run", "--scene", str(scene)]))
    assert "unknown scene key 'dampng'; did you mean 'damping'?" in err
    scene.write_text("springs: {stifness: [1.0, 1.0]}\n")
    err = one_line(capsys, cli.main(["run", "--scene", str(scene)]))
    assert "did you mean 'springs.stiffness'?" in err
    with pytest.raises(ParameterRefused, match="unknown parameter; did you mean 'damping'?"):
        resolve_parameters({"dampng": 0.3})


def test_ros_arguments_without_ros_args_get_the_command_line_that_takes_them(capsys):
    """`arm_sim_node -p scene:=x` got argparse's line and no hint."""
    err = one_line(capsys, node_main.main(["-p", "scene:=x"]))
    assert err == ("arm_sim_node: error: unrecognized arguments: -p scene:=x; ROS arguments go "
                   "after --ros-args: arm_sim_node --ros-args -p scene:=x\n")
    err = one_line(capsys, node_main.main(["--duration", "1", "--params-file", "p.yaml"]))
    assert err.endswith("; ROS arguments go after --ros-args: arm_sim_node --duration 1 "
                        "--ros-args --params-file p.yaml\n")
    err = one_line(capsys, node_main.main(["--frob"]))
    assert err == "arm_sim_node: error: unrecognized arguments: --frob\n"
