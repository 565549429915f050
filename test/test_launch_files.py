"""config/arm_sim.yaml and launch/arm_sim.launch.py agree with what the node declares."""
import ast
import importlib.util
from pathlib import Path

import pytest
import yaml

from arm_sim_ros.interface import NODE_NAME
from arm_sim_ros.node.parameters import SPECS, resolve_parameters

ROOT = Path(__file__).resolve().parents[1]
PARAMS = ROOT / "config" / "arm_sim.yaml"
LAUNCH = ROOT / "launch" / "arm_sim.launch.py"


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


def launch_tree():
    return ast.parse(LAUNCH.read_text(), filename=str(LAUNCH))


def test_launch_file_defines_generate_launch_description():
    functions = [n.name for n in launch_tree().body if isinstance(n, ast.FunctionDef)]
    assert "generate_launch_description" in functions


def test_launch_arguments_are_scene_publish_rate_and_params_file():
    declared = {call.args[0].value for call in ast.walk(launch_tree())
                if isinstance(call, ast.Call) and getattr(call.func, "id", "") == "DeclareLaunchArgument"}
    assert declared == {"scene", "publish_rate", "params_file"}


def test_launch_starts_the_node_and_robot_state_publisher():
    nodes = []
    for call in ast.walk(launch_tree()):
        if isinstance(call, ast.Call) and getattr(call.func, "id", "") == "Node":
            nodes.append({k.arg: k.value.value for k in call.keywords
                          if isinstance(k.value, ast.Constant)})
    assert {(n["package"], n["executable"]) for n in nodes} == {
        ("arm_sim_ros", "arm_sim_node"), ("robot_state_publisher", "robot_state_publisher")}
    assert next(n for n in nodes if n["package"] == "arm_sim_ros")["name"] == NODE_NAME


def test_launch_description_builds_where_ros_is_installed():
    for module in ("launch", "launch_ros", "ament_index_python"):
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"{module} is not installed (no ROS 2 sourced)")
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    try:
        get_package_share_directory("arm_sim_ros")
    except PackageNotFoundError:
        pytest.skip("arm_sim_ros is not installed in an ament prefix (colcon build)")
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument

    spec = importlib.util.spec_from_file_location("arm_sim_launch", LAUNCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    assert isinstance(description, LaunchDescription)
    names = {a.name for a in description.entities if isinstance(a, DeclareLaunchArgument)}
    assert names == {"scene", "publish_rate", "params_file"}
