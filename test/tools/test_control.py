"""arm_sim_controllers (tools/control): the claims of the active controllers turned into the
node's servo.interface, a start only from a finite state, and its command line with no ROS."""
from __future__ import annotations

import importlib.util
from math import inf, nan
from pathlib import Path

import pytest
import yaml

from arm_sim_ros.interface import JOINT_NAMES
from arm_sim_ros.tools.control.claims import (claimed_interfaces, interfaces_for, started_from,
                                              unknown_active)
from arm_sim_ros.tools.control.follower import main
from arm_sim_ros.usage import REFUSED

ROOT = Path(__file__).resolve().parents[2]
CONTROLLERS = yaml.safe_load((ROOT / "config" / "ros2_controllers.yaml").read_text())


def required(name):
    """A controller's command interfaces as ListControllers gives them once configured."""
    config = CONTROLLERS[name]["ros__parameters"]
    kinds = config.get("command_interfaces") or [config["interface_name"]]
    return [f"{joint}/{kind}" for joint in config["joints"] for kind in kinds]


KNOWN = {name: required(name) for name in CONTROLLERS
         if name not in ("controller_manager", "joint_state_broadcaster")}


@pytest.mark.parametrize("active, expected", [
    ("position_trajectory_controller", ["position", "position"]),   # position and velocity
    ("effort_trajectory_controller", ["effort", "effort"]),
    ("forward_effort_controller", ["effort", "effort"]),
    ("forward_velocity_controller", ["velocity", "velocity"]),
])
def test_each_shipped_controller_sets_the_interface_it_claims(active, expected):
    states = {name: "inactive" for name in KNOWN} | {active: "active",
                                                      "joint_state_broadcaster": "active"}
    claimed = claimed_interfaces(KNOWN, states)
    assert interfaces_for(claimed, JOINT_NAMES, ["effort", "velocity"]) == expected


def test_a_joint_no_active_controller_claims_keeps_its_interface():
    """Between a deactivation and an activation (two separate switches) the hardware goes on
    sending what the last controller left: the joint goes on taking it."""
    assert interfaces_for(set(), JOINT_NAMES, ["effort", "position"]) == ["effort", "position"]
    one = {"elbow_joint/velocity"}
    assert interfaces_for(one, JOINT_NAMES, ["effort", "position"]) == ["effort", "velocity"]


def test_a_controller_whose_interfaces_are_not_known_yet_is_asked_about():
    states = {"forward_velocity_controller": "active", "mine": "active", "other": "inactive"}
    assert unknown_active(KNOWN, states) == ["mine"]
    assert unknown_active(KNOWN, {"forward_velocity_controller": "active"}) == []


@pytest.mark.parametrize("positions, started", [
    ([0.3, 0.6], True), ([nan, nan], False), ([0.3, nan], False), ([], False),
    ([inf, 0.0], False)])
def test_the_controllers_start_only_from_a_finite_state(positions, started):
    assert started_from(positions) is started


def test_without_ros_the_command_line_says_what_it_needs_in_one_line(capsys):
    if importlib.util.find_spec("rclpy") is not None:
        pytest.skip("rclpy imports here")
    assert main(["arm_sim_controllers", "follow"]) == REFUSED
    err = capsys.readouterr().err
    assert err.startswith("arm_sim_controllers: needs ROS 2 Jazzy") and err.count("\n") == 1


def test_a_bad_command_line_is_refused_in_one_line(capsys):
    assert main(["arm_sim_controllers", "fly"]) == REFUSED
    assert "invalid choice: 'fly'" in capsys.readouterr().err


def test_the_package_installs_it_as_a_ros_executable():
    """In lib/arm_sim_ros (setup.cfg), where `ros2 run` and the launch's Node look."""
    assert ('"arm_sim_controllers = arm_sim_ros.tools.control.follower:main"'
            in (ROOT / "setup.py").read_text())
