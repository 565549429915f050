"""The shipped ros2_control fragment, controller configuration and launch file agree with the
node, and the wire contract of ros-controls' joint_state_topic_hardware_interface holds on
the dds transport: its commands (sensor_msgs/JointState, reliable, keep-last 1: a position,
velocity and effort per joint, NaN where no controller claims it) drive the arm, and its
subscription (SensorDataQoS: best effort, keep-last 5) receives joint_states. The shipped
trajectory controllers' gains are run against the node as controller_manager would run
them. No ROS needed; domains 146-147."""
import ast
import logging
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml
from cyclonedds.core import Policy, Qos
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from arm_sim_ros.interface import JOINT_NAMES, NODE_NAME
from arm_sim_ros.node.wire import messages as msg
from arm_sim_ros.node.core import ArmSimCore
from arm_sim_ros.node.params.parameters import SPECS, resolve_parameters
from arm_sim_ros.node.transports import TRANSPORTS
from arm_sim_ros.node.transports.dds import DdsArmSimNode
from node.ros2_control_loop import Core, Manager, TrajectoryController
from node.test_node_dds import CONFIG, TIMEOUT, wait_until

ROOT = Path(__file__).resolve().parents[2]
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


def test_the_fragments_joints_are_the_urdfs_with_every_command_interface_and_its_limits():
    joints = BLOCK.findall("joint")
    assert [j.get("name") for j in joints] == list(JOINT_NAMES)
    urdf = ET.parse(ROOT / "urdf" / "two_link_arm.urdf").getroot()
    assert set(JOINT_NAMES) <= {j.get("name") for j in urdf.findall("joint")}
    for joint in joints:
        commands = {c.get("name"): {p.get("name"): float(p.text) for p in c.findall("param")}
                    for c in joint.findall("command_interface")}
        assert list(commands) == ["position", "velocity", "effort"]
        # no initial_value: an unclaimed interface stays NaN, which the node reads as unset
        torque_limit = SPECS["torque_limit"].default
        assert commands["effort"] == {"min": -torque_limit, "max": torque_limit}
        assert commands["velocity"]["min"] == -commands["velocity"]["max"] > -100.0
        assert [s.get("name") for s in joint.findall("state_interface")] == \
            ["position", "velocity", "effort"]


def test_controller_manager_clamps_commands_to_the_fragments_limits():
    """Jazzy's controller_manager takes a command interface's min/max as the joint's limit
    (the URDF's continuous joints declare none) but enforces limits only when asked: an
    effort above torque_limit then reaches the node, which refuses it."""
    manager = yaml.safe_load((ROOT / "config" / "ros2_controllers.yaml").read_text())
    assert manager["controller_manager"]["ros__parameters"]["enforce_command_limits"] is True


CONTROLLERS = yaml.safe_load((ROOT / "config" / "ros2_controllers.yaml").read_text())


def test_the_controllers_drive_both_joints_at_the_nodes_rate():
    manager = CONTROLLERS["controller_manager"]["ros__parameters"]
    assert manager["update_rate"] == SPECS["publish_rate"].default
    types = {name: manager[name]["type"] for name in manager if isinstance(manager[name], dict)}
    assert types == {
        "joint_state_broadcaster": "joint_state_broadcaster/JointStateBroadcaster",
        "position_trajectory_controller": "joint_trajectory_controller/JointTrajectoryController",
        "effort_trajectory_controller": "joint_trajectory_controller/JointTrajectoryController",
        "forward_effort_controller": "forward_command_controller/ForwardCommandController",
        "forward_velocity_controller": "forward_command_controller/ForwardCommandController"}
    for name, interface in (("forward_effort_controller", "effort"),
                            ("forward_velocity_controller", "velocity")):
        forward = CONTROLLERS[name]["ros__parameters"]
        assert forward["joints"] == list(JOINT_NAMES) and forward["interface_name"] == interface


@pytest.mark.parametrize("name, interfaces", [
    ("position_trajectory_controller", ["position", "velocity"]),
    ("effort_trajectory_controller", ["effort"])])
def test_each_trajectory_controller_names_its_interfaces_and_goal_tolerances(name, interfaces):
    config = CONTROLLERS[name]["ros__parameters"]
    assert config["joints"] == list(JOINT_NAMES)
    assert config["command_interfaces"] == interfaces
    assert config["state_interfaces"] == ["position", "velocity"]
    constraints = config["constraints"]
    assert constraints["goal_time"] > 0 and constraints["stopped_velocity_tolerance"] > 0
    for joint in JOINT_NAMES:
        assert 0 < constraints[joint]["goal"] <= 0.01 and constraints[joint]["trajectory"] > 0
    if interfaces == ["effort"]:
        assert set(config["gains"]) == set(JOINT_NAMES)


def follow(controller, policy, target=(0.8, -0.4), duration=2.0):
    """A JointTrajectoryController as controller_manager runs it at update_rate against the
    node (ros2_control_loop.py: a JointState command per cycle, the state read before): the
    guide's goal to `target`, then goal_time more. (largest deviation from the reference,
    final error, largest |effort| commanded)."""
    config = CONTROLLERS[controller]["ros__parameters"]
    core = ArmSimCore(resolve_parameters({"scene": "servo_hold", "policy": policy,
                                          "servo.interface": [config["command_interfaces"][0]]
                                          * 2}),
                      logging.getLogger("test_ros2_control"), wall_clock=lambda: 0.0,
                      start_stamp_ns=0)
    dt = 1.0 / CONTROLLERS["controller_manager"]["ros__parameters"]["update_rate"]
    trajectory = TrajectoryController(controller, config, dt)
    manager = Manager(Core(core), {controller: trajectory})
    manager.switch(controller)
    manager.cycle()
    trajectory.goal(target, duration)
    deviation = peak = 0.0
    for _ in range(round((duration + config["constraints"]["goal_time"]) / dt)):
        manager.cycle()
        deviation = max(deviation, *(abs(r - q) for r, q in zip(trajectory.reference()[0],
                                                                  core.sim.state)))
        if trajectory.interface == "effort":
            peak = max(peak, *(abs(manager.commands[(j, "effort")]) for j in JOINT_NAMES))
    return deviation, max(abs(q - t) for q, t in zip(core.sim.state, target)), peak


@pytest.mark.parametrize("controller, policy", [
    ("position_trajectory_controller", "command_gravity_compensation"),
    ("position_trajectory_controller", "command"),
    ("effort_trajectory_controller", "command_gravity_compensation"),
    ("effort_trajectory_controller", "command")])
def test_the_shipped_gains_reach_the_goal_within_its_tolerance_on_the_default_scene(
        controller, policy):
    deviation, error, peak = follow(controller, policy)
    constraints = CONTROLLERS[controller]["ros__parameters"]["constraints"]
    assert error < constraints["shoulder_joint"]["goal"]
    assert deviation < constraints["shoulder_joint"]["trajectory"]
    assert peak < SPECS["torque_limit"].default       # never refused as too large


def launch_function(name):
    (function,) = [f for f in LAUNCH.body if isinstance(f, ast.FunctionDef) and f.name == name]
    return function


def test_the_launch_files_node_parameters_are_the_nodes():
    (call,) = [n for n in ast.walk(launch_function("controlled")) if isinstance(n, ast.Call)
               and any(k.arg == "executable" and getattr(k.value, "value", None) == "arm_sim_node"
                       for k in n.keywords)]
    (parameters,) = [k.value for k in call.keywords if k.arg == "parameters"]
    given = {ast.literal_eval(k): v for k, v in zip(parameters.elts[0].left.keys,
                                                   parameters.elts[0].left.values)}
    assert set(given) | {"servo.interface"} <= set(SPECS)
    literal = {k: ast.literal_eval(v) for k, v in given.items() if isinstance(v, ast.Constant)}
    config = resolve_parameters(literal | {"scene": "servo_hold"})
    # the fragment's topics (above) are the node's, as the launch file starts it
    assert config.values["joint_commands_topic"] == "joint_commands"
    assert config.values["joint_states_topic"] == "joint_states"
    assert config.values["command_timeout"] > 0        # a stale command is never held forever


def test_the_launch_picks_a_controller_the_config_carries_and_the_interface_it_claims():
    namespace = launch_constants()
    for choice, (controller, interface) in namespace["CONTROLLERS"].items():
        claimed = CONTROLLERS[controller]["ros__parameters"]
        assert interface == claimed.get("interface_name", claimed.get("command_interfaces",
                                                                      [None])[0])
    arguments = {call.args[0].value: call for call in ast.walk(LAUNCH) if isinstance(call, ast.Call)
                 and getattr(call.func, "id", "") == "DeclareLaunchArgument"}
    assert set(arguments) == {"scene", "policy", "controller", "use_sim_time", "lockstep", "rviz",
                              "transport"}
    defaults = {name: next(k.value.value for k in call.keywords if k.arg == "default_value")
                for name, call in arguments.items()}
    assert defaults["controller"] in namespace["CONTROLLERS"]
    assert defaults["transport"] in ("auto",) + TRANSPORTS       # arm_sim_node --transport
    # the arm starts held: the default scene's servos hold its initial pose
    config = resolve_parameters({"scene": defaults["scene"], "policy": defaults["policy"]})
    assert config.scene.servo is not None


def launch_constants():
    namespace = {}
    exec(compile(ast.Module([n for n in LAUNCH.body if isinstance(n, ast.Assign)], []),
                 "launch", "exec"), namespace)
    return namespace


def test_the_launch_loads_every_controller_of_the_config_one_active_the_others_inactive():
    """So that `ros2 control switch_controllers` finds each one ready to activate."""
    manager = CONTROLLERS["controller_manager"]["ros__parameters"]
    configured = {name for name in manager if isinstance(manager[name], dict)}
    offered = {controller for controller, _ in launch_constants()["CONTROLLERS"].values()}
    assert offered == configured - {"joint_state_broadcaster"}
    source = ast.unparse(launch_function("controlled"))
    assert "'--inactive'" in source and "if name != controller" in source


def test_the_controllers_start_once_the_hardware_has_read_the_nodes_state():
    """A controller activated before the hardware's first read holds NaN (a JTC's state
    showed NaN until its first goal): the spawners run when `arm_sim_controllers wait` ends
    well, which it does once the joint_state_broadcaster publishes a finite state."""
    function = launch_function("controlled")
    (handler,) = [n for n in ast.walk(function) if isinstance(n, ast.Call)
                  and getattr(n.func, "id", "") == "OnProcessExit"]
    keywords = {k.arg: ast.unparse(k.value) for k in handler.keywords}
    assert keywords == {"target_action": "waiter", "on_exit": "started"}
    (started,) = [n for n in ast.walk(function) if isinstance(n, ast.FunctionDef)
                  and n.name == "started"]
    assert "event.returncode == 0" in ast.unparse(started)
    (waiter,) = [n for n in ast.walk(function) if isinstance(n, ast.Assign)
                 and ast.unparse(n.targets[0]) == "waiter"]
    assert "executable='arm_sim_controllers'" in ast.unparse(waiter)
    assert "arguments=['wait']" in ast.unparse(waiter)


def test_the_launch_follows_every_switch_into_servo_interface():
    (follower,) = [n for n in ast.walk(LAUNCH) if isinstance(n, ast.Call) and any(
        k.arg == "executable" and getattr(k.value, "value", None) == "arm_sim_controllers"
        for k in n.keywords) and "follow" in ast.unparse(n)]
    assert "'follow'" in ast.unparse(follower)


def test_the_launch_needs_no_lockstep_wait_of_its_own():
    """The node's default waits while a node listens on /clock: a launch written without it
    does not deadlock with controller_manager under use_sim_time."""
    assert "lockstep_wait" not in ast.unparse(launch_function("controlled"))
    assert SPECS["lockstep_wait"].default > 0


def test_controller_manager_gets_no_robot_description_parameter():
    """ros2_control_node (Jazzy) reads /robot_description from robot_state_publisher."""
    (call,) = [n for n in ast.walk(LAUNCH) if isinstance(n, ast.Call) and any(
        k.arg == "executable" and getattr(k.value, "value", None) == "ros2_control_node"
        for k in n.keywords)]
    assert "robot_description" not in ast.unparse(call)


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


def test_the_hardware_interfaces_position_commands_drive_the_servos_on_the_wire():
    """What it writes for a position trajectory controller: all three fields per joint, the
    unclaimed ones NaN."""
    node = DdsArmSimNode({"scene": "servo_hold", "command_timeout": 0.0}, domain_id=147,
                         config=CONFIG, wall_clock=lambda: 0.0, start_stamp_ns=0)
    p = msg.make_participant(147, CONFIG)
    commands = DataWriter(p, Topic(p, "rt/joint_commands", msg.JointState), qos=Qos(
        Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
        Policy.Durability.Volatile, Policy.History.KeepLast(1)))
    wait_until(lambda: msg.matched(commands), "the hardware interface's publisher did not match")
    nan = float("nan")
    commands.write(msg.JointState(name=list(JOINT_NAMES), position=[0.5, 0.2],
                                  velocity=[0.0, 0.0], effort=[nan, nan]))
    assert node.take_commands(timeout=TIMEOUT) == 1 and node.core.refused_commands == 0
    for _ in range(300):
        node.tick()
    assert max(abs(q - t) for q, t in zip(node.core.sim.state, (0.5, 0.2))) < 1e-3
    node.close()
