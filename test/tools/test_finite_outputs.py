"""No output holds a number that is not finite (issue 47): a run that cannot stay finite holds
its last finite state and writes finite rows (a step not estimated leaves its error cells
empty); a scene whose start is already beyond double precision is refused in one line, by
the same rule offline, at the node's start and live."""
import json
import logging

import pytest

from arm_sim_ros.node import core as node_core
from arm_sim_ros.node.params import parameters as node_params
from arm_sim_ros.tools import cli

from tools.finite_outputs import bag_places, csv_places, json_places, rrd_places

# Held from the first step: a step that leaves the doubles; a step the stability plan cannot
# take (damping far beyond it: not estimated either)
HELD = {"release": ["--set", "initial_velocities=5e153,-5e153"],
        "servo_hold": ["--set", "initial_velocities=5e153,-5e153",
                       "--set", "sensors.position_noise=0.01,0.01",
                       "--set", "sensors.velocity=differences"],
        "damped_release": ["--set", "damping=1e9"]}


@pytest.mark.parametrize("scene", HELD)
def test_a_run_that_holds_writes_only_finite_numbers(capsys, tmp_path, scene):
    """Every output holds the last finite state, and no cell, value or message a number
    that is not finite (the CSV's error books held nan where the steps are not estimated)."""
    code = cli.main(["run", "--scene", scene, *HELD[scene], "--duration", "0.05", "--json",
                     "--csv", str(tmp_path / "r.csv"), "--rerun", str(tmp_path / "r.rrd"),
                     "--bag", str(tmp_path / "bag")])
    out, err = capsys.readouterr()
    assert code == 1 and "holding the last finite state" in err
    result = json.loads(out)
    assert result["refused_steps"] > 0 and result["t"] == 0.05     # time ran on
    assert json_places(result) == set()
    assert csv_places(tmp_path / "r.csv") == set()
    assert rrd_places(tmp_path / "r.rrd") == set()
    assert bag_places(tmp_path / "bag") == set()


BEYOND = [("release", "initial_velocities", [1e300, -1e300]),
          ("moving_gravity_compensation", "gravity", 1e308),
          ("wrong_payload_model", "controller_model.gravity", 1e308),
          ("springs_oscillation", "springs.rest_positions", [1e308, 0.0]),
          ("compliant_limit", "joint_limits.stiffness", 1e308)]


@pytest.mark.parametrize("scene, key, value", BEYOND)
def test_a_start_beyond_double_precision_is_refused_alike_offline_at_start_and_live(
        capsys, scene, key, value):
    """Its energy, its torque or its step plan is not finite from the start: such a run held
    at once, its outputs inf or NaN (a node froze at stamp 0); refused by one rule."""
    text = ",".join(map(repr, value)) if isinstance(value, list) else repr(value)
    code = cli.main(["run", "--scene", scene, "--set", f"{key}={text}", "--duration", "0.05"])
    out, err = capsys.readouterr()
    assert code == 2 and out == "" and err.count("\n") == 1 and "double precision" in err
    with pytest.raises(node_params.ParameterRefused) as refused:     # the node's start
        node_core.ArmSimCore(node_params.resolve_parameters({"scene": scene, key: value}),
                             logging.getLogger("beyond"))
    assert "double precision" in refused.value.reason
    core = node_core.ArmSimCore(node_params.resolve_parameters({"scene": scene}),
                                logging.getLogger("beyond"))
    core.tick()
    before = (core.config, core.sim.state, core.sim.steps)
    with pytest.raises(node_params.ParameterRefused):
        core.set_parameters({key: value})
    assert (core.config, core.sim.state, core.sim.steps) == before
