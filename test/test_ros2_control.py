"""The shipped ros2_control fragment, controller configuration and launch file agree with the
node, and the wire contract of ros-controls' joint_state_topic_hardware_interface holds on
the dds transport: its commands (sensor_msgs/JointState with efforts only, reliable,
keep-last 1) drive the arm, and its subscription (SensorDataQoS: best effort, keep-last 5)
receives joint_states. No ROS needed; domains 146-147."""
import ast
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import yaml
from cyclonedds.core import Policy, Qos
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from arm_sim_ros.interface import JOINT_NAMES, NODE_NAME
from arm_sim_ros.node import messages as msg
from arm_sim_ros.node.parameters import SPECS, resolve_parameters
from arm_sim_ros.node.transports.dds import DdsArmSimNode
from test_node_dds import CONFIG, TIMEOUT, wait_until

ROOT = Path(__file__).resolve().parents[1]
BLOCK = ET.fromstring((ROOT / "urdf" / "two_link_arm.ros2_control.xml").read_text())
LAUNCH = ast.parse((ROOT / "launch" / "arm_sim_ros2_control.launch.py").read_text())


def test_the_fragment_uses_the_topic_based_system_on_the_nodes_topics():
    hardware = BLOCK.find("hardware")
    assert hardware.find("plugin").text == "joint_state_topic_hardware_interface/JointStateTopicSystem"
    params = {p.get("name"): p.text for p in hardware.findall("param")}
    assert params["joint_commands_topic"] == "/" + SPECS["joint_commands_topic"].default
    assert params["joint_states_topic"] == "/" + SPECS["joint_states_topic"].default
    assert float(params["trigger_joint_command_threshold"]) < 0    # every effort is sent


def test_the_hardware_is_not_named_like_the_node():
    """controller_manager makes a node of the hardware's name: `arm_sim` there made a second
    /arm_sim, and `ros2 param` reached whichever answered first (seen on a real one)."""
    assert BLOCK.tag == "ros2_control" and BLOCK.get("name") not in ("", None, NODE_NAME)


def test_the_fragments_joints_are_the_urdfs_with_effort_commands():
    joints = BLOCK.findall("joint")
    assert [j.get("name") for j in joints] == list(JOINT_NAMES)
    urdf = ET.parse(ROOT / "urdf" / "two_link_arm.urdf").getroot()
    assert set(JOINT_NAMES) <= {j.get("name") for j in urdf.findall("joint")}
    for joint in joints:
        assert [c.get("name") for c in joint.findall("command_interface")] == ["effort"]
        assert [s.get("name") for s in joint.findall("state_interface")] == \
            ["position", "velocity", "effort"]


def test_the_controllers_drive_both_joints_at_the_nodes_rate():
    config = yaml.safe_load((ROOT / "config" / "ros2_controllers.yaml").read_text())
    manager = config["controller_manager"]["ros__parameters"]
    assert manager["effort_controller"]["type"] == \
        "forward_command_controller/ForwardCommandController"   # JointGroupEffortController's
    assert manager["joint_state_broadcaster"]["type"] == \
        "joint_state_broadcaster/JointStateBroadcaster"
    effort = config["effort_controller"]["ros__parameters"]
    assert effort["joints"] == list(JOINT_NAMES) and effort["interface_name"] == "effort"
    assert manager["update_rate"] == SPECS["publish_rate"].default


def test_the_launch_files_node_parameters_are_the_nodes():
    (call,) = [n for n in ast.walk(LAUNCH) if isinstance(n, ast.Call)
               and any(k.arg == "executable" and getattr(k.value, "value", None) == "arm_sim_node"
                       for k in n.keywords)]
    (parameters,) = [k.value for k in call.keywords if k.arg == "parameters"]
    given = {ast.literal_eval(k): v for k, v in zip(parameters.elts[0].keys,
                                                   parameters.elts[0].values)}
    assert set(given) <= set(SPECS)
    literal = {k: ast.literal_eval(v) for k, v in given.items() if isinstance(v, ast.Constant)}
    config = resolve_parameters(literal | {"scene": "gravity_compensation_at_rest"})
    # the fragment's topics (above) are the node's, as the launch file starts it
    assert config.values["joint_commands_topic"] == "joint_commands"
    assert config.values["joint_states_topic"] == "joint_states"


def test_the_hardware_interfaces_qos_and_messages_drive_the_node():
    node = DdsArmSimNode({"policy": "command", "gravity": 0.0}, domain_id=146, config=CONFIG,
                         wall_clock=lambda: 0.0, start_stamp_ns=0)
    p = msg.make_participant(146, CONFIG)
    # rclcpp::QoS(1) for its command publisher, SensorDataQoS for its state subscription
    commands = DataWriter(p, Topic(p, "rt/joint_commands", msg.JointState), qos=Qos(
        Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
        Policy.Durability.Volatile, Policy.History.KeepLast(1)))
    states = DataReader(p, Topic(p, "rt/joint_states", msg.JointState), qos=Qos(
        Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(5)))
    wait_until(lambda: msg.matched(commands) and msg.matched(states),
               "the hardware interface's endpoints did not match")
    commands.write(msg.JointState(header=msg.Header(stamp=msg.Time(12, 0)),
                                  name=list(JOINT_NAMES), effort=[3.0, -1.0]))
    assert node.take_commands(timeout=TIMEOUT) == 1 and node.core.command == (3.0, -1.0)
    node.tick()
    received, deadline = [], time.monotonic() + TIMEOUT
    while not received and time.monotonic() < deadline:
        received = [s for s in states.take(N=10) if isinstance(s, msg.JointState)]
        time.sleep(0.001)
    assert received and list(received[0].name) == list(JOINT_NAMES)
    node.close()
