"""`arm-sim scenes` and `arm-sim run`: outputs, overrides, and one-line refusals with exit code 2."""
import csv
import json
import math
import subprocess
import sys

import pytest

from arm_sim_ros.physics.compiled import build as compiled
from arm_sim_ros.tools import cli
from arm_sim_ros.physics.scene import load_scene, preset_names
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.recording import csv_file

PRESETS = {"release", "shoulder_torque_no_gravity", "gravity_compensation_at_rest",
           "moving_gravity_compensation", "moving_frozen_gravity", "damped_release",
           "downward_equilibrium"}


def run_cli(capsys, *argv):
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


EFFECT_PRESETS = {"per_joint_damping", "springs_oscillation", "payload_release", "geared_release",
                  "motor_windings_hold", "effort_limited_hold", "wrong_payload_model", "geared_arm",
                  "stick_slip", "limit_impact", "compliant_limit", "servo_hold", "servo_reach"}


def test_scenes_lists_the_explainers_seven_and_the_effect_presets_with_descriptions(capsys):
    code, out, _ = run_cli(capsys, "scenes")
    assert code == 0
    assert set(preset_names()) == PRESETS | EFFECT_PRESETS
    for name in PRESETS | EFFECT_PRESETS:
        line = next(l for l in out.splitlines() if l.split()[0] == name)
        assert load_scene(name).description in line


def test_run_json_has_the_documented_keys_and_values(capsys):
    code, out, _ = run_cli(capsys, "run", "--scene", "release", "--json")
    assert code == 0
    result = json.loads(out)
    assert set(result) == {"t", "q", "qd", "tau", "kinetic", "potential", "total", "work", "dissipated",
                           "channels", "residual", "max_abs_energy_drift", "fault",
                           "refused_steps", "interrupted_at", "error_estimate",
                           "accumulated_error", "estimate", "path"}
    assert result["path"] == ("compiled (numba)" if compiled.available() else "python")
    assert result["channels"] == {}          # the release has no actuator and no damping
    assert result["t"] == 0.5
    assert [f"{x:.6f}" for x in result["q"]] == ["-1.122654", "0.593820"]


def test_run_overrides_turn_release_into_the_shoulder_torque_scene(capsys):
    code, out, _ = run_cli(capsys, "run", "--json", "--set", "gravity=0", "--set", "policy=constant",
                           "--set", "constant_torque=1,0")
    assert code == 0
    sim = Simulator(load_scene("shoulder_torque_no_gravity"))
    sim.run(0.5)
    assert json.loads(out)["q"] == list(sim.state[:2])


def test_run_step_and_duration_from_the_command_line(capsys):
    code, out, _ = run_cli(capsys, "run", "--step", "0.005", "--duration", "2", "--json",
                           "--tolerance", "0")      # the explainer's program: plain RK4
    assert f"{json.loads(out)['max_abs_energy_drift']:.9f}" == "0.000011084"


def test_run_prints_state_and_energy(capsys):
    code, out, _ = run_cli(capsys, "run", "--scene", "damped_release")
    assert code == 0
    for text in ("t = 2.000000 s", "q = (", "qd = (", "tau = (0.000000, 0.000000)", "dissipated",
                 "balance residual"):
        assert text in out


def test_csv_has_initial_row_plus_one_per_step(capsys, tmp_path):
    path = tmp_path / "run.csv"
    code, _, _ = run_cli(capsys, "run", "--scene", "damped_release", "--csv", str(path))
    assert code == 0
    rows = list(csv.DictReader(path.open()))
    assert list(rows[0]) == list(csv_file.CSV_COLUMNS)
    assert list(rows[0])[-2:] == ["error_estimate", "accumulated_error"]
    assert len(rows) == 201
    assert float(rows[0]["t"]) == 0.0 and float(rows[-1]["t"]) == 2.0
    last = rows[-1]
    assert float(last["total"]) == pytest.approx(float(last["kinetic"]) + float(last["potential"]), abs=1e-12)
    assert float(last["dissipated"]) > 0


@pytest.mark.parametrize("argv, fragment", [
    (["run", "--scene", "nope"], "unknown scene 'nope'"),
    (["run", "--set", "bogus=1"], "unknown scene key 'bogus'"),
    (["run", "--set", "gravity"], "not of the form key=value"),
    (["run", "--set", "gravity=abc"], "gravity='abc' is malformed"),
    (["run", "--set", "constant_torque=1"], "constant_torque needs two numbers"),
    (["run", "--set", "damping=inf"], "damping = inf is not finite"),
    (["run", "--set", "gravity=nan"], "gravity = nan is not finite"),
    (["run", "--step", "0"], "step_size = 0.0 must be positive"),
    (["run", "--step", "-0.01"], "must be positive"),
    (["run", "--duration", "0.503"], "not a whole number of steps"),
    (["run", "--set", "link_masses=0,1"], "link_masses[0] = 0.0 is impossible"),
    (["run", "--set", "link_lengths=1,-2"], "link_lengths[1] = -2.0 is impossible"),
    (["run", "--set", "com_inertias=-1,0.1"], "com_inertias[0] = -1.0 is impossible"),
    (["run", "--set", "policy=teleport"], "policy 'teleport' is unknown"),
    (["run", "--set", "damping=-1"], "would add energy"),
    (["run", "--set", "initial_positions=1e300,0"], "initial_positions = [1e+300, 0.0] is beyond 1e+06 rad"),
    (["run", "--csv", "/nonexistent-dir/x.csv"], "--csv /nonexistent-dir/x.csv: the directory /nonexistent-dir does not exist"),
    (["run", "--rerun", "/nonexistent-dir/x.rrd"], "the directory /nonexistent-dir does not exist"),
    (["run", "--rerun", "x.txt"], "--rerun x.txt: the name must end in .rrd"),
    (["run", "--publish-rate", "50"], "--publish-rate sets the JointState rate of a --bag recording"),
    (["frobnicate"], "invalid choice"),
])
def test_bad_input_is_one_line_on_stderr_with_exit_code_2(capsys, argv, fragment):
    code, out, err = run_cli(capsys, *argv)
    assert code == 2
    assert out == ""
    assert len(err.strip().splitlines()) == 1
    assert fragment in err


def test_console_script_refuses_without_traceback():
    proc = subprocess.run([sys.executable, "-m", "arm_sim_ros.tools.cli", "run", "--set", "link_masses=-1,1"],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert proc.stderr.startswith("arm-sim: error: link_masses[0] = -1.0 is impossible")


def test_run_prints_the_error_estimate_with_its_units_and_the_tolerance(capsys):
    """The latest step's local error estimate and their sum, as --json has them, in the
    text output: rad, rad/s (max over q, q̇), and what holds them."""
    held = ("--scene", "damped_release", "--set", "tolerance=0.002")
    code, out, _ = run_cli(capsys, "run", *held, "--json")
    result = json.loads(out)
    code, out, _ = run_cli(capsys, "run", *held)
    assert code == 0
    line = out.splitlines()[-1]
    assert line == (f"error estimate: latest step {result['error_estimate']:.3e}, accumulated "
                    f"{result['accumulated_error']:.3e} (rad, rad/s: max over q, qd); "
                    "tolerance 0.002 per s (scaled: max |e_q|, |e_qd|/(1+|qd|))")
    sim = Simulator(load_scene("damped_release").replace(tolerance=0.002))
    sim.run(2.0)
    assert result["accumulated_error"] == sim.accumulated_error > result["error_estimate"] > 0
    _, out, _ = run_cli(capsys, "run", "--set", "tolerance=0")
    assert out.splitlines()[-1].endswith("; tolerance 0 (estimate only)")
    _, out, _ = run_cli(capsys, "run", "--set", "integrator=dopri5")
    assert out.splitlines()[-1].endswith("; rtol 1e-08, atol 1e-10 (dopri5)")


# Damping far beyond the stability planner's reach: every step is refused, none estimated.
UNESTIMATED = ("--scene", "damped_release", "--set", "damping=1e9", "--duration", "0.05")


def test_a_run_without_an_estimate_prints_n_a_and_null(capsys):
    assert math.isnan(Simulator(load_scene("damped_release").replace(damping=1e9)).error_estimate)
    _, out, _ = run_cli(capsys, "run", *UNESTIMATED)
    assert "error estimate: latest step n/a, accumulated n/a (rad, rad/s" in out
    _, out, _ = run_cli(capsys, "run", *UNESTIMATED, "--json")
    result = json.loads(out)
    assert result["error_estimate"] is None and result["accumulated_error"] is None


def test_csv_rows_carry_each_steps_error_estimate_and_their_sum(capsys, tmp_path):
    path = tmp_path / "books.csv"
    assert run_cli(capsys, "run", "--scene", "stick_slip", "--csv", str(path),
                   "--duration", "0.5")[0] == 0
    rows = list(csv.DictReader(path.open()))
    sim = Simulator(load_scene("stick_slip"))
    expected = [(sim.error_estimate, sim.accumulated_error)]
    sim.run(0.5, lambda s: expected.append((s.error_estimate, s.accumulated_error)))
    assert [(float(r["error_estimate"]), float(r["accumulated_error"])) for r in rows] == expected
    assert float(rows[-1]["accumulated_error"]) > 0
    run_cli(capsys, "run", *UNESTIMATED, "--csv", str(path), "--force")
    rows = list(csv.DictReader(path.open()))
    assert {r["error_estimate"] for r in rows} == {r["accumulated_error"] for r in rows} == {""}
