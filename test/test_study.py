"""The accuracy study: its reference reproduces the explainer, its numbers and fits are
right, and `arm-sim accuracy` writes a table, JSON and a plot, refusing bad input."""
import json
from math import isinf

import pytest

from arm_sim_ros.tools import cli, accuracy as study
from arm_sim_ros.physics.scene import load_scene


def printed(values):
    return "(" + ", ".join(f"{x:.6f}" for x in values) + ")"


def reference_at(scene_name, t):
    return study.reference(load_scene(scene_name), [0.0, t])[-1]


# The reference itself reproduces the explainer's figures.

def test_reference_release_at_half_a_second():
    y = reference_at("release", 0.5)
    assert printed(y[:2]) == "(-1.122654, 0.593820)"
    # The explainer's qd are RK4 figures (h = 0.005 shown); the reference lies within 1e-6.
    assert y[2:4] == pytest.approx((-2.414308, -3.534796), abs=1e-6)


def test_reference_shoulder_torque_work_equals_the_shoulder_angle():
    y = reference_at("shoulder_torque_no_gravity", 0.5)
    assert f"{y[0]:.6f}" == "0.202009"
    assert y[4] == pytest.approx(y[0], abs=1e-12)        # W = q1(t) - q1(0)


def test_reference_moving_arms():
    y = reference_at("moving_gravity_compensation", 0.5)
    assert printed(y[:4]) == "(0.250000, 0.000000, 0.500000, 0.000000)"
    y = reference_at("moving_frozen_gravity", 0.5)
    assert printed(y[:2]) == "(0.258510, -0.011739)"
    assert printed(y[2:4]) == "(0.570046, -0.099129)"


def test_reference_exercise_two_work_is_the_potential_gain():
    y = reference_at("moving_gravity_compensation", 1.0)
    assert printed(y[:2]) == "(0.500000, 0.000000)"
    assert f"{y[4]:.6f}" == "9.406329"


def test_study_reports_the_explainers_energy_drift_for_rk4():
    result = study.study(load_scene("release"), 2.0, ["rk4"], [0.01, 0.005], [])
    residuals = [r["balance_residual"] for r in result["runs"]]
    assert [f"{x:.9f}" for x in residuals] == ["0.000145388", "0.000011084"]


# Measurements and fits.

def test_rk4_fitted_order_in_the_study_is_four():
    result = study.study(load_scene("release"), 0.5, ["rk4"], [0.01, 0.005, 0.0025, 0.00125], [])
    assert result["orders"]["rk4"]["fitted"] == pytest.approx(4.0, abs=0.1)
    evaluations = [r["rhs_evaluations"] for r in result["runs"]]
    assert evaluations == [200, 400, 800, 1600]             # four stages per step


def test_fitted_order_recovers_a_power_law_and_skips_points_out_of_range():
    runs = [study.Run("x", h, None, 3.0 * h ** 3, 0, 0, 0, 0) for h in (0.1, 0.05, 0.025)]
    runs.append(study.Run("x", 0.0125, None, 1e-15, 0, 0, 0, 0))  # round-off floor: ignored
    assert study.fitted_order(runs) == pytest.approx(3.0, abs=1e-12)
    assert study.fitted_order(runs[3:]) is None


def test_a_diverging_run_counts_as_infinitely_wrong():
    scene = load_scene("release")
    times = study.sample_times(scene, 0.5, 0.5)
    ref = study.reference(scene, times)
    run = study.measure(scene.replace(initial_velocities=(1e200, 1e200)), "euler", 0.25, None,
                        times, ref)
    assert isinf(run.max_state_error) and isinf(run.balance_residual)


def test_dopri5_runs_at_the_publish_step_for_each_tolerance():
    result = study.study(load_scene("release"), 0.5, ["dopri5"], [], [1e-6, 1e-10])
    loose, tight = result["runs"]
    assert loose["step_size"] == tight["step_size"] == 0.01
    assert tight["max_state_error"] < loose["max_state_error"]
    assert tight["rhs_evaluations"] > loose["rhs_evaluations"]
    assert result["orders"] == {}


def test_cheapest_picks_the_least_cpu_time_that_reaches_the_target():
    result = {"runs": [{"max_state_error": 1e-7, "cpu_s_per_sim_s": 2.0},
                       {"max_state_error": 1e-5, "cpu_s_per_sim_s": 0.5},
                       {"max_state_error": 5e-7, "cpu_s_per_sim_s": 1.0}]}
    assert study.cheapest(result, 1e-6)["cpu_s_per_sim_s"] == 1.0
    assert study.cheapest(result, 1e-9) is None


# The command.

def test_accuracy_command_writes_table_json_and_plot(tmp_path, capsys):
    out_json, out_png = tmp_path / "r.json", tmp_path / "p.png"
    code = cli.main(["accuracy", "--duration", "0.5", "--integrators", "rk4", "midpoint", "dopri5",
                     "--steps", "0.01", "0.005", "--tolerances", "1e-8",
                     "--json", str(out_json), "--plot", str(out_png)])
    assert code == 0
    captured = capsys.readouterr()
    assert "fitted order rk4" in captured.out and "dopri5" in captured.out
    assert captured.err == ""                # work this short shows no progress
    data = json.loads(out_json.read_text())
    assert {r["integrator"] for r in data["runs"]} == {"rk4", "midpoint", "dopri5"}
    assert out_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("argv, message", [
    (["--integrators", "leapfrog"], "unknown integrator 'leapfrog'"),
    (["--steps", "0.01", "0.003"], "--steps 0.003 does not divide 0.01, the largest step"),
    (["--steps", "1e-300"], "the study allows 1e+07 per run"),
    (["--plot", "out.txt"], "--plot out.txt: the name must end in .png or .svg or .pdf"),
    (["--steps", "-0.01"], "must be a finite number above 0"),
    (["--tolerances", "2"], "below 1"),
    (["--tolerances", "1e-300"], "above 1e-14"),
    (["--duration", "nan"], "positive number of seconds"),
    (["--steps", "x"], "invalid float value"),
])
def test_accuracy_command_refuses_bad_input_in_one_line(argv, message, capsys):
    assert cli.main(["accuracy", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_accuracy_command_refuses_an_unwritable_json_path_before_the_study(tmp_path, capsys):
    code = cli.main(["accuracy", "--duration", "0.1", "--integrators", "rk4", "--steps", "0.01",
                     "--json", str(tmp_path / "missing" / "r.json")])
    assert code == 2
    out, err = capsys.readouterr()
    assert out == "" and "missing does not exist" in err     # nothing ran


def test_the_study_runs_a_scene_with_extra_states_and_channels(capsys):
    """Windings add currents to the state and three channels: the reference and every run
    carry them (the reference integrates the scene's own right-hand side)."""
    code = cli.main(["accuracy", "--scene", "motor_windings_hold", "--duration", "0.05",
                     "--integrators", "rk4", "--steps", "0.0005", "0.00025"])
    out = capsys.readouterr().out
    assert code == 0 and "rk4" in out and "fitted order" in out
