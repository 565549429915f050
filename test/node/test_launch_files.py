"""config/arm_sim.yaml, launch/arm_sim.launch.py and rviz/arm_sim.rviz agree with what the
node declares and what the shipped URDF holds."""
import ast
import importlib
import importlib.util
import logging
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml

from arm_sim_ros.interface import NODE_NAME
from arm_sim_ros.node.params.parameters import SPECS, resolve_parameters

ROOT = Path(__file__).resolve().parents[2]
PARAMS = ROOT / "config" / "arm_sim.yaml"
LAUNCH = ROOT / "launch" / "arm_sim.launch.py"
CONTROL_LAUNCH = ROOT / "launch" / "arm_sim_ros2_control.launch.py"
RVIZ = ROOT / "rviz" / "arm_sim.rviz"
URDF = ROOT / "urdf" / "two_link_arm.urdf"
ARGUMENTS = {"scene", "publish_rate", "params_file", "rviz"}


@pytest.fixture(scope="module")
def parameters():
    return yaml.safe_load(PARAMS.read_text())[NODE_NAME]["ros__parameters"]


def test_params_file_is_for_the_arm_sim_node(parameters):
    assert list(yaml.safe_load(PARAMS.read_text())) == ["arm_sim"]
    assert parameters


def test_params_file_names_only_declared_parameters(parameters):
    assert set(parameters) <= set(SPECS), set(parameters) - set(SPECS)


def test_params_file_is_accepted_by_the_node(parameters):
    config = resolve_parameters(parameters)
    for name, value in parameters.items():
        assert config.values[name] == value
    assert config.steps_per_tick == 10  # 1 kHz physics, 100 Hz joint_states


def test_params_file_values(parameters):
    # No scene here: a node section in a params file wins over `-p scene:=...` (as in rclcpp).
    assert "scene" not in parameters
    assert parameters["step_size"] == 0.001
    assert parameters["publish_rate"] == 100.0
    assert parameters["command_timeout"] == 0.5
    assert parameters["torque_limit"] == SPECS["torque_limit"].default   # launched = unlaunched
    assert parameters["joint_names"] == ["shoulder_joint", "elbow_joint"]
    assert parameters["rerun_path"] == ""


def launch_tree(path=LAUNCH):
    return ast.parse(path.read_text(), filename=str(path))


def launched_nodes(path=LAUNCH):
    """Each Node(...) of a launch file: its constant keywords, its arguments' constants and
    whether it has a condition."""
    nodes = []
    for call in ast.walk(launch_tree(path)):
        if isinstance(call, ast.Call) and getattr(call.func, "id", "") == "Node":
            keywords = {k.arg: k.value for k in call.keywords}
            node = {k: v.value for k, v in keywords.items() if isinstance(v, ast.Constant)}
            node["arguments"] = [a.value for a in getattr(keywords.get("arguments"), "elts", [])
                                 if isinstance(a, ast.Constant)]
            node["conditional"] = "condition" in keywords
            nodes.append(node)
    return nodes


def test_launch_file_defines_generate_launch_description():
    functions = [n.name for n in launch_tree().body if isinstance(n, ast.FunctionDef)]
    assert "generate_launch_description" in functions


def test_launch_arguments_are_scene_publish_rate_params_file_and_rviz():
    declared = {call.args[0].value for call in ast.walk(launch_tree())
                if isinstance(call, ast.Call) and getattr(call.func, "id", "") == "DeclareLaunchArgument"}
    assert declared == ARGUMENTS


def test_launch_starts_the_node_robot_state_publisher_and_rviz_on_request():
    nodes = launched_nodes()
    assert {(n["package"], n["executable"]) for n in nodes} == {
        ("arm_sim_ros", "arm_sim_node"), ("robot_state_publisher", "robot_state_publisher"),
        ("rviz2", "rviz2")}
    assert next(n for n in nodes if n["package"] == "arm_sim_ros")["name"] == NODE_NAME
    (rviz,) = [n for n in nodes if n["package"] == "rviz2"]
    assert rviz["conditional"] and rviz["arguments"] == ["-d"]    # -d <share>/rviz/arm_sim.rviz
    assert not any(n["conditional"] for n in nodes if n["package"] != "rviz2")


def test_the_ros2_control_launch_file_offers_rviz_too():
    nodes = launched_nodes(CONTROL_LAUNCH)
    assert [n["conditional"] for n in nodes if n["package"] == "rviz2"] == [True]


def test_setup_installs_the_rviz_config():
    shares = [tuple(a.value for a in call.args) for call in ast.walk(ast.parse((ROOT / "setup.py").read_text()))
              if isinstance(call, ast.Call) and getattr(call.func, "id", "") == "share"]
    assert ("rviz", "*.rviz") in shares and RVIZ.is_file()


# --- rviz/arm_sim.rviz --------------------------------------------------------------------

@pytest.fixture(scope="module")
def rviz():
    return yaml.safe_load(RVIZ.read_text())["Visualization Manager"]


def display(rviz, kind):
    (found,) = [d for d in rviz["Displays"] if d["Class"] == f"rviz_default_plugins/{kind}"]
    assert found["Enabled"] is True
    return found


def test_rviz_shows_the_robot_from_robot_description_and_tf(rviz):
    model = display(rviz, "RobotModel")
    assert model["Description Source"] == "Topic"
    # robot_state_publisher publishes it transient local: a later RViz still gets it
    assert model["Description Topic"]["Value"] == "/robot_description"
    assert model["Description Topic"]["Durability Policy"] == "Transient Local"
    assert display(rviz, "TF")["Frames"]["All Enabled"] is True


def test_rvizs_fixed_frame_is_the_urdfs_root(rviz):
    robot = ET.parse(URDF).getroot()
    children = {j.find("child").get("link") for j in robot.iter("joint")}
    roots = [l.get("name") for l in robot.iter("link") if l.get("name") not in children]
    assert [rviz["Global Options"]["Fixed Frame"]] == roots == ["base_link"]


def test_rvizs_camera_looks_at_the_arms_plane_from_its_counter_clockwise_side(rviz):
    view = rviz["Views"]["Current"]
    assert view["Class"] == "rviz_default_plugins/Orbit"
    # rviz_default_plugins' OrbitViewController: the camera sits at the focal point plus
    # Distance (cos Yaw cos Pitch, sin Yaw cos Pitch, sin Pitch), z up.
    yaw, pitch, distance = view["Yaw"], view["Pitch"], view["Distance"]
    eye = distance * np.array([math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch),
                               math.sin(pitch)])
    # the joint axes in base_link: arm_plane's +z turned by plane_joint's roll
    roll = float(next(j for j in ET.parse(URDF).getroot().iter("joint")
                      if j.get("name") == "plane_joint").find("origin").get("rpy").split()[0])
    axis = np.array([0.0, -math.sin(roll), math.cos(roll)])
    assert eye @ axis / distance > 0.95            # nearly square-on, from where CCW is CCW
    focal = [view["Focal Point"][k] for k in "XYZ"]
    assert focal == [0, 0, 0]                      # the shoulder
    # the whole reach (2 m every way) within RViz's default 45° vertical field of view
    assert distance * math.tan(math.radians(22.5)) > 2.0 * 1.2


def ament_share(tmp_path, monkeypatch):
    """An ament prefix holding this source tree's files, as colcon would install them; skips
    where launch cannot import."""
    # Importing launch swaps the logger class for one that does not propagate to pytest's
    # capture; later tests' loggers would be lost (seen with ROS sourced): put it back.
    monkeypatch.setattr(logging, "_loggerClass", logging.getLoggerClass())
    for module in ("launch", "launch_ros", "ament_index_python"):
        try:
            importlib.import_module(module)
        except ImportError as error:   # not sourced, or its own dependencies (lark) missing
            pytest.skip(f"{module} cannot be imported (no ROS 2 sourced?): {error}")
    share = tmp_path / "share"
    (share / "ament_index" / "resource_index" / "packages").mkdir(parents=True)
    (share / "ament_index" / "resource_index" / "packages" / "arm_sim_ros").touch()
    (share / "arm_sim_ros").mkdir()
    for folder in ("config", "urdf", "rviz", "launch"):
        (share / "arm_sim_ros" / folder).symlink_to(ROOT / folder)
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path))


def load_launch(path):
    spec = importlib.util.spec_from_file_location(path.stem.replace(".", "_"), path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_launch_description_builds_where_ros_is_installed(tmp_path, monkeypatch):
    ament_share(tmp_path, monkeypatch)
    from launch import LaunchContext, LaunchDescription
    from launch.actions import DeclareLaunchArgument
    from launch_ros.actions import Node

    description = load_launch(LAUNCH).generate_launch_description()
    assert isinstance(description, LaunchDescription)
    names = {a.name for a in description.entities if isinstance(a, DeclareLaunchArgument)}
    assert names == ARGUMENTS
    context = LaunchContext()
    for rviz_argument, launched in (("false", False), ("true", True)):
        context.launch_configurations["rviz"] = rviz_argument
        (rviz2,) = [n for n in description.entities if isinstance(n, Node)
                    and n.node_package == "rviz2"]
        assert rviz2.condition.evaluate(context) is launched


def test_the_ros2_control_launch_builds_each_controller_where_ros_is_installed(tmp_path,
                                                                                monkeypatch):
    ament_share(tmp_path, monkeypatch)
    from launch import LaunchContext
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    module = load_launch(CONTROL_LAUNCH)
    description = module.generate_launch_description()
    context = LaunchContext()
    for argument in description.entities:
        if isinstance(argument, DeclareLaunchArgument):
            context.launch_configurations[argument.name] = argument.default_value[0].text
    (opaque,) = [e for e in description.entities if isinstance(e, OpaqueFunction)]
    for choice, (controller, _) in module.CONTROLLERS.items():
        context.launch_configurations["controller"] = choice
        node, waiter, handler = opaque.execute(context)
        assert node.node_package == waiter.node_package == "arm_sim_ros"
        assert waiter.node_executable == "arm_sim_controllers"
        assert handler.__class__.__name__ == "RegisterEventHandler"
    context.launch_configurations["controller"] = "torque"
    with pytest.raises(ValueError, match="controller:=torque is not one of"):
        opaque.execute(context)
