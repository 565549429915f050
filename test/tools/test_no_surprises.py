"""No quiet surprises: what the tools replace, guess or start from, they say.

--urdf names every scene value it replaced; an initial angle beyond a full turn warns (and
degrees are written `90deg`); an unknown preset gets a "did you mean"; the node stops on
SIGINT even when it was started with SIGINT ignored; a live change says what changed; and
/clock and the stamps start at 0 unless `clock_origin: wall` asks for the wall clock.
"""
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from arm_sim_ros.node import core as node_core
from arm_sim_ros.node.params import parameters as node_params
from arm_sim_ros.physics.scene import SceneError, load_scene
from arm_sim_ros.tools import cli

BIN = Path(sys.executable).parent


def test_urdf_names_every_scene_value_it_replaced_in_one_line(tmp_path, capsys):
    urdf = tmp_path / "arm.urdf"
    assert cli.main(["urdf", "--scene", "limit_impact", "-o", str(urdf)]) == 0
    capsys.readouterr()
    assert cli.main(["run", "--scene", "damped_release", "--urdf", str(urdf),
                     "--duration", "0.1"]) == 0
    out, err = capsys.readouterr()
    assert err.splitlines() == [f"arm-sim: --urdf {urdf} replaced in scene damped_release: "
                                "damping 0.5 -> 0; joint_limits none -> {lower, upper}"]
    assert out.startswith("scene damped_release on arm.urdf:")   # the header says whose arm


def test_urdf_of_the_scenes_own_arm_says_nothing_was_replaced(tmp_path, capsys):
    urdf = tmp_path / "arm.urdf"
    assert cli.main(["urdf", "--scene", "release", "-o", str(urdf)]) == 0
    capsys.readouterr()
    assert cli.main(["run", "--urdf", str(urdf), "--duration", "0.1"]) == 0
    assert "nothing replaced" in capsys.readouterr().err


def test_the_node_says_what_its_robot_description_replaced(tmp_path, capsys):
    urdf = tmp_path / "arm.urdf"
    assert cli.main(["urdf", "--scene", "limit_impact", "-o", str(urdf)]) == 0
    log = ListLog()
    config = node_params.resolve_parameters({"scene": "damped_release",
                                             "robot_description": urdf.read_text()})
    node_core.ArmSimCore(config, log, wall_clock=lambda: 0.0).finish()
    assert [m for _, m in log.lines if "started" in m] == [
        "scene damped_release started: policy command, h = 0.01 s, rk4, 1 steps per tick; "
        "estimate global, tolerance 5e-05; robot_description replaced: damping 0.5 -> 0; joint_limits none -> {lower, upper}"]


def test_an_initial_angle_beyond_a_full_turn_warns_once_and_suggests_degrees(capsys):
    assert cli.main(["run", "--set", "initial_positions=90,-30", "--duration", "0.1"]) == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert warnings == ["arm-sim: warning: initial_positions [90.0, -30.0] rad: 90 rad is more "
                        "than a full turn (2π = 6.283 rad); angles are radians. If you meant "
                        "degrees, write initial_positions=90deg,-30deg"]


def test_angles_may_be_written_in_degrees_and_then_nothing_warns(capsys):
    assert cli.main(["run", "--set", "initial_positions=90deg,-30deg", "--duration", "0",
                     "--json"]) == 0
    out, err = capsys.readouterr()
    assert "warning" not in err
    assert json.loads(out)["q"] == [math.radians(90), math.radians(-30)]


def test_only_angles_take_degrees(capsys):
    assert cli.main(["run", "--set", "gravity=9deg"]) == 2
    assert "only angles take deg" in capsys.readouterr().err


def test_the_node_warns_of_an_initial_angle_beyond_a_full_turn_with_the_degrees_it_takes():
    log = ListLog()
    config = node_params.resolve_parameters({"initial_positions": [90.0, 0.0]})
    node_core.ArmSimCore(config, log, wall_clock=lambda: 0.0).finish()
    assert [m for level, m in log.lines if level == "warning"] == [
        "initial_positions [90.0, 0.0] rad: 90 rad is more than a full turn (2π = 6.283 rad); "
        "angles are radians. If you meant degrees, write -p \"initial_positions:=[90deg, 0deg]\""]


def test_a_misspelt_preset_gets_a_did_you_mean():
    with pytest.raises(SceneError, match=r"unknown scene 'geared-arm'; did you mean 'geared_arm'\?"):
        load_scene("geared-arm")
    with pytest.raises(SceneError) as nothing_close:
        load_scene("xyzzy")
    assert "did you mean" not in str(nothing_close.value)


class ListLog:
    def __init__(self):
        self.lines = []

    def info(self, message):
        self.lines.append(("info", message))

    def warning(self, message):
        self.lines.append(("warning", message))

    error = warning
    debug = info


def test_a_live_change_names_what_changed_and_only_that():
    log = ListLog()
    config = node_params.resolve_parameters({"scene": "damped_release"})
    core = node_core.ArmSimCore(config, log, wall_clock=lambda: 0.0)
    core.tick(0.0)
    core.set_parameters({"damping": 0.3})
    core.set_parameters({"payload.mass": 0.5})
    changes = [m for _, m in log.lines if " at t = " in m]
    assert changes == [
        "damping -> 0.3 at t = 0.010000 s: the motion carries on from the current state",
        "payload.mass -> 0.5 at t = 0.010000 s: the motion carries on from the current state; "
        "the payload's energy is booked in payload_exchange"]


# --- the clock's origin -------------------------------------------------------------------

def test_clock_and_stamps_start_at_zero_by_default():
    config = node_params.resolve_parameters({"publish_rate": 50.0})
    core = node_core.ArmSimCore(config, ListLog(), wall_clock=lambda: 0.0)
    assert [core.tick(0.0).stamp_ns for _ in range(3)] == [20_000_000, 40_000_000, 60_000_000]


def test_clock_origin_wall_starts_at_the_wall_clock():
    before = time.time_ns()
    config = node_params.resolve_parameters({"publish_rate": 50.0, "clock_origin": "wall"})
    core = node_core.ArmSimCore(config, ListLog(), wall_clock=lambda: 0.0)
    stamp = core.tick(0.0).stamp_ns
    assert before + 20_000_000 <= stamp <= time.time_ns() + 20_000_000


def test_clock_origin_is_checked_and_start_only():
    with pytest.raises(node_params.ParameterRefused, match="must be one of zero, wall"):
        node_params.resolve_parameters({"clock_origin": "gazebo"})
    config = node_params.resolve_parameters({})
    with pytest.raises(node_params.ParameterRefused, match="start-only"):
        config.with_changes({"clock_origin": "wall"})


# --- SIGINT ---------------------------------------------------------------------------------

def test_the_node_stops_on_sigint_even_when_started_with_sigint_ignored(tmp_path):
    """`cmd &` in a script starts it with SIGINT ignored; Python would keep it ignored."""
    env = dict(os.environ, ROS_DOMAIN_ID="208", ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    node = subprocess.Popen([str(BIN / "arm_sim_node"), "--transport", "dds"],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    try:
        assert "started" in node.stderr.readline()
        node.send_signal(signal.SIGINT)
        assert node.wait(timeout=20) == 0
    finally:
        if node.poll() is None:
            node.kill()
            node.wait()
