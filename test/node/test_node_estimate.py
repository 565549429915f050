"""The node's `estimate` parameter (issue 35): `-p estimate:=off` as a ROS user types it. rcl
reads an unquoted `off` as the bool false; the node takes it back as the word, and estimate
off alone sets the tolerance to 0, at start and live, as a scene file does."""
import pytest

from arm_sim_ros.node.core import ArmSimCore
from arm_sim_ros.node.params.parameters import resolve_parameters
from arm_sim_ros.node.params.values import ParameterRefused
from arm_sim_ros.node.params.ros_args import node_parameters, parse_ros_args


class Log:
    def info(self, message):
        pass

    warning = error = debug = info


def test_minus_p_estimate_off_is_off_with_no_tolerance():
    overrides = node_parameters(parse_ros_args(["-p", "estimate:=off"]), "arm_sim", "/")
    assert overrides == {"estimate": False}          # what rcl makes of it
    config = resolve_parameters(overrides)
    assert config.scene.estimate == "off" and config.values["estimate"] == "off"
    assert config.scene.tolerance == 0.0 and config.values["tolerance"] == 0.0


def test_estimate_off_with_a_tolerance_named_beside_it_is_refused():
    with pytest.raises(ParameterRefused, match="estimate off computes no error estimate"):
        resolve_parameters({"estimate": "off", "tolerance": 1e-6})


def test_a_live_estimate_off_sets_the_tolerance_to_0_and_says_both_changed():
    core = ArmSimCore(resolve_parameters({}), Log(), wall_clock=lambda: 0.0)
    assert core.set_parameters({"estimate": False}) == ["tolerance", "estimate"]
    assert core.sim.scene.estimate == "off" and core.config.values["tolerance"] == 0.0
    core.finish()
