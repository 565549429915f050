"""Sensors at the edge of double precision (issue 47): one rule decides what is accepted, the
same in a scene file, on the command line, at the node's start and live; what it accepts
reads finite numbers; and integer keys stay integers end to end."""
from __future__ import annotations

import logging
from math import isfinite

import pytest

from arm_sim_ros.node import core as node_core
from arm_sim_ros.node.params import parameters as node_params
from arm_sim_ros.physics.scene import Scene, SceneError, load_scene
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.recording.rrd import readback
from arm_sim_ros.tools import cli

AT_REST = Scene(gravity=0.0, step_size=1e-3)      # q = 0 for ever: a reading is its error


def run_cli(capsys, *argv):
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


# -- what the rule accepts reads finite numbers ------------------------------------------------

@pytest.mark.parametrize("resolution, offset", [(1e-310, 0.0), (5e-324, 0.5), (1e-300, 1e6),
                                                (1e-320, -1e6), (2.2e-308, 1e-3)])
def test_a_resolution_finer_than_a_double_reads_the_angle_itself(resolution, offset):
    """A count beyond the doubles (x / 1e-310) means a resolution finer than x's own
    rounding: x is a whole count already, and the reading is x, never an OverflowError."""
    sim = Simulator(AT_REST.replace(sensors={"position_resolution": [resolution] * 2,
                                             "position_offset": [offset] * 2}))
    for _ in range(3):
        sim.step()
        assert sim.readings[:2] == (offset, offset)


@pytest.mark.parametrize("command", ["run", "excite"])
def test_the_command_line_runs_a_resolution_of_1e_310(capsys, tmp_path, command):
    argv = ["--set", "sensors.position_resolution=1e-310,1e-310", "--duration", "1"]
    argv += ["--csv", str(tmp_path / "r.csv")] if command == "run" else [str(tmp_path / "bag")]
    code, _, err = run_cli(capsys, command, *argv)
    assert code == 0, err


# -- one rule: a scene file, --set, the node's start and a live set ------------------------------

@pytest.mark.parametrize("key, value", [("position_noise", 1e306), ("position_offset", -1e308),
                                        ("position_resolution", 1e300),
                                        ("velocity_noise", 1e306), ("position_noise", 2e6)])
def test_a_reading_beyond_the_largest_angle_is_refused_alike_everywhere(capsys, tmp_path, key,
                                                                         value):
    """A noise of 1e306 rad read inf (its differences over a period overflow): refused by
    every way in, in one line naming the key, with nothing changed live; at the bound
    (1e6 rad, the largest angle) the readings, and a servo's torques from them, are finite."""
    name = f"sensors.{key}"
    for scene in ("release", "servo_hold"):
        sim = Simulator(load_scene(scene).replace(
            sensors={"velocity": "differences" if key != "velocity_noise" else "true",
                     key: (1e6, 1e6 if key != "position_offset" else -1e6)}))
        for _ in range(20):
            sim.step()
            assert all(isfinite(v) for v in sim.readings + sim.joint_torque() + sim.state)
    with pytest.raises(SceneError, match=name):
        AT_REST.replace(**{name: (value, value)})
    scene_file = tmp_path / "s.yaml"
    scene_file.write_text(f"sensors:\n  velocity: differences\n  {key}: [{value!r}, {value!r}]\n")
    code, out, err = run_cli(capsys, "run", "--scene", str(scene_file))
    assert code == 2 and out == "" and err.count("\n") == 1 and name in err
    code, out, err = run_cli(capsys, "run", "--set", f"{name}={value!r},{value!r}",
                             "--set", "sensors.velocity=differences")
    assert code == 2 and out == "" and err.count("\n") == 1 and name in err
    with pytest.raises(node_params.ParameterRefused) as refused:
        node_params.resolve_parameters({name: [value, value]})
    assert refused.value.name == name
    core = node_core.ArmSimCore(node_params.resolve_parameters({"sensors.velocity": "differences"}),
                                logging.getLogger("edges"))
    core.tick()
    before = (core.config, core.sim.state)
    with pytest.raises(node_params.ParameterRefused) as refused:
        core.set_parameters({name: [value, value]})
    assert refused.value.name == name and (core.config, core.sim.state) == before


# -- integer keys stay integers ---------------------------------------------------------------

def test_seeds_beyond_2_to_53_are_streams_of_their_own():
    """A seed held as a double collapsed 2^60 - 1, 2^60 and 2^60 + 1 into one stream."""
    seeds = (2 ** 60 - 1, 2 ** 60, 2 ** 60 + 1, 2 ** 63 - 1)
    read = []
    for seed in seeds:
        sim = Simulator(AT_REST.replace(sensors={"seed": seed, "position_noise": [0.1, 0.1]}))
        sim.step()
        read.append(sim.readings[:2])
    assert len(set(read)) == len(seeds)


def test_integer_keys_stay_integers_end_to_end(capsys, tmp_path):
    """The documented largest seed, 2^63 - 1, through a scene file, --set, a node parameter
    (an integer, or a whole double below 2^53) and a recording's properties: the same int."""
    largest = 2 ** 63 - 1
    scene_file = tmp_path / "s.yaml"
    scene_file.write_text(f"max_substeps: 64\nsensors:\n  seed: {largest}\n")
    scene = load_scene(str(scene_file))
    assert scene.sensors["seed"] == largest and type(scene.max_substeps) is int
    config = node_params.resolve_parameters({"sensors.seed": largest, "max_substeps": 64.0})
    assert config.scene.sensors["seed"] == largest and config.values["max_substeps"] == 64
    assert type(config.scene.max_substeps) is int
    path = tmp_path / "seed.rrd"
    code, _, err = run_cli(capsys, "run", "--set", f"sensors.seed={largest}",
                           "--set", "max_substeps=64", "--duration", "0.05", "--rerun", str(path))
    assert code == 0, err
    recorded = readback.properties(path)["scene"]
    assert f'"seed": {largest}' in recorded["sensors"] and recorded["max_substeps"] == 64
    with pytest.raises(node_params.ParameterRefused, match="2\\^53"):
        node_params.resolve_parameters({"sensors.seed": float(2 ** 60)})   # which integer?
