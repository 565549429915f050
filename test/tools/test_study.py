"""The accuracy study: its reference reproduces the explainer, its numbers and fits are
right, and `arm-sim accuracy` writes a table, JSON and a plot, refusing bad input."""
import json
import sys
from math import isfinite, isinf

import pytest

from arm_sim_ros.tools import cli
from arm_sim_ros.tools.accuracy import command as study
from arm_sim_ros.tools.accuracy.runs import MJ_STEP, ROLLOUT
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator


def series(result, name):
    return [r for r in result["runs"] if r["series"] == name]


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
    residuals = [r["balance_residual"] for r in series(result, "rk4")]
    assert [f"{x:.9f}" for x in residuals] == ["0.000145388", "0.000011084"]


# Measurements and fits.

def test_rk4_fitted_order_in_the_study_is_four():
    result = study.study(load_scene("release"), 0.5, ["rk4"], [0.01, 0.005, 0.0025, 0.00125], [])
    assert result["orders"]["rk4"]["fitted"] == pytest.approx(4.0, abs=0.1)
    assert [r["step_size"] for r in series(result, "rk4")] == [0.01, 0.005, 0.0025, 0.00125]


def test_fitted_order_recovers_a_power_law_and_skips_points_out_of_range():
    runs = [study.Run("x", h, None, 3.0 * h ** 3, 0, 0) for h in (0.1, 0.05, 0.025)]
    runs.append(study.Run("x", 0.0125, None, 1e-15, 0, 0))  # round-off floor: ignored
    assert study.fitted_order(runs) == pytest.approx(3.0, abs=1e-12)
    assert study.fitted_order(runs[3:]) is None


@pytest.mark.parametrize("estimate", study.ESTIMATES)
def test_a_diverging_run_counts_as_infinitely_wrong(estimate):
    scene = load_scene("release")
    times = study.sample_times(scene, 0.5, 0.5)
    ref = study.reference(scene, times)
    run = study.measure(scene.replace(initial_velocities=(5e153, 5e153)), "euler", 0.25, None,
                        times, ref, estimate).run
    assert isinf(run.max_state_error) and isinf(run.balance_residual)


def test_dopri5_runs_at_the_publish_step_for_each_tolerance():
    result = study.study(load_scene("release"), 0.5, ["dopri5"], [], [1e-6, 1e-10])
    loose, tight = series(result, "dopri5")
    assert loose["step_size"] == tight["step_size"] == 0.01
    assert tight["max_state_error"] < loose["max_state_error"]
    assert result["orders"] == {}


def test_cheapest_picks_the_least_cpu_time_that_reaches_the_target():
    result = {"runs": [{"max_state_error": 1e-7, "cpu_s_per_sim_s": 2.0},
                       {"max_state_error": 1e-5, "cpu_s_per_sim_s": 0.5},
                       {"max_state_error": 5e-7, "cpu_s_per_sim_s": 1.0}]}
    assert study.cheapest(result, 1e-6)["cpu_s_per_sim_s"] == 1.0
    assert study.cheapest(result, 1e-9) is None


# The command.

def test_accuracy_command_writes_table_json_and_plot(tmp_path, capsys, monkeypatch):
    from arm_sim_ros.tools import progress
    monkeypatch.setattr(progress, "QUIET_FOR", float("inf"))   # a loaded machine's wall time
    out_json, out_png = tmp_path / "r.json", tmp_path / "p.png"
    code = cli.main(["accuracy", "--duration", "0.5", "--integrators", "rk4", "midpoint", "dopri5",
                     "--steps", "0.01", "0.005", "--tolerances", "1e-8", "--tolerance-sweep",
                     "1e-6", "--repeat", "1", "--json", str(out_json), "--plot", str(out_png)])
    assert code == 0
    captured = capsys.readouterr()
    assert "fitted order rk4" in captured.out and "dopri5" in captured.out
    assert captured.err == ""                # nothing but progress goes to stderr
    data = json.loads(out_json.read_text())
    ours = {r["integrator"] for r in data["runs"] if not r["series"].startswith("mujoco")}
    assert ours == {"rk4", "midpoint", "dopri5"}
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
    (["--peers", "bullet"], "unknown peer 'bullet'; choose from mujoco or none"),
    (["--repeat", "0"], "--repeat 0 must be at least 1"),
    (["--tolerance-sweep", "0"], "--tolerance-sweep value 0 must be a finite number above 0"),
    (["--scenes", "release", "no_such_scene"], "no_such_scene"),
    (["--plot", "/nonexistent/dir/p.png"], "the directory /nonexistent/dir does not exist"),
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
    carry them (the reference integrates the scene's own right-hand side), and rk4 keeps
    its order there (measured 4.58 over these two steps)."""
    code = cli.main(["accuracy", "--scene", "motor_windings_hold", "--duration", "0.05",
                     "--integrators", "rk4", "--steps", "0.0005", "0.00025"])
    out = capsys.readouterr().out
    assert code == 0 and "rk4" in out and "fitted order" in out
    result = study.study(load_scene("motor_windings_hold"), 0.05, ["rk4"], [0.0005, 0.00025], [])
    assert 3.5 < result["orders"]["rk4"]["fitted"] < 5.0


# The price list: the tolerance setting, the effect scenes, MuJoCo side by side.

def test_the_tolerance_sweep_achieved_error_falls_as_the_tolerance_tightens():
    result = study.study(load_scene("release"), 1.0, ["rk4"], [0.01], [],
                         sweep=[1e-3, 1e-6, 1e-9])
    swept = series(result, "rk4 + tolerance")
    assert [r["tolerance"] for r in swept] == [1e-3, 1e-6, 1e-9]
    achieved = [r["max_state_error"] for r in swept]
    taken = [r["substeps"] for r in swept]
    assert achieved[0] >= achieved[1] >= achieved[2] and achieved[2] < achieved[0] / 100
    assert taken[0] <= taken[1] < taken[2]           # the accuracy is bought with sub-steps
    assert all(r["step_size"] == 0.01 for r in swept)


def test_the_tolerance_sweep_runs_exactly_where_the_steps_carry_an_estimate():
    """A tolerance acts through the step's error estimate: a scene that switches modes
    carries one, so it is swept; where the stability plan refuses the steps they carry none
    (NaN), the sweep would repeat one run, so it is left out and the study says why."""
    result = study.study(load_scene("stick_slip"), 0.5, ["rk4"], [0.01], [], sweep=[1e-6])
    said = any("no error estimate" in note for note in result["notes"])
    assert (len(series(result, "rk4 + tolerance")), said) == (1, False)
    refused = load_scene("damped_release").replace(damping=1e9)     # no reference computed
    plan, notes, _ = study.plan_runs(refused, [0.0, 0.5], None, ["rk4"], [0.01], [], [1e-6],
                                     ())
    swept = [label for label, _ in plan if "tolerance=" in label]
    said = [note for note in notes if "no error estimate" in note]
    assert (len(swept), len(said)) == (0, 1) and "stability plan refuses" in said[0]


def test_a_scene_that_switches_modes_is_compared_with_a_reference_that_locates_switches():
    """The study's runs of stick_slip go through Simulator.step (which locates the switches)
    and converge at RK4's order to an independent reference: DOP853 with the switches as
    terminal events, on equations written apart (tools/accuracy/independent.py)."""
    result = study.study(load_scene("stick_slip"), 1.0, ["rk4"], [0.01, 0.005, 0.0025], [])
    assert "terminal events" in result["reference"] and "written apart" in result["reference"]
    errors = [r["max_state_error"] for r in series(result, "rk4")]
    assert errors[0] > 8 * errors[1] > 64 * errors[2] and errors[2] < 1e-6


SAME_PHYSICS = ["release", "damped_release", "springs_oscillation", "payload_release",
                "geared_release", "shoulder_torque_no_gravity", "moving_gravity_compensation"]


@pytest.mark.parametrize("name", SAME_PHYSICS)
def test_mujoco_runs_beside_ours_and_its_rk4_agrees_with_ours_where_the_physics_is_the_same(name):
    pytest.importorskip("mujoco", reason="MuJoCo is the [bench] extra: pip install '.[bench]'")
    result = study.study(load_scene(name), 1.0, ["rk4"], [0.01, 0.005], [], peers=["mujoco"])
    runs = {(r["series"], r["step_size"]): r for r in result["runs"]}
    assert {s for s, _ in runs if s.startswith("mujoco")} == {
        f"mujoco {i}{how}" for i in ("Euler", "implicit", "implicitfast", "RK4")
        for how in ("", " rollout")}
    for h in (0.01, 0.005):
        ours, theirs = runs[("rk4", h)], runs[("mujoco RK4", h)]
        # The same scheme on the same equations: the same error against the same reference.
        assert theirs["max_state_error"] == pytest.approx(ours["max_state_error"],
                                                          rel=1e-6, abs=1e-12)
        assert theirs["max_state_error"] < 1e-4 and theirs["cpu_s_per_sim_s"] > 0
        rolled = runs[("mujoco RK4 rollout", h)]   # the same steps, in MuJoCo's own loop
        assert rolled["max_state_error"] == theirs["max_state_error"]
    assert "floor" not in result["peers"]["mujoco"]


def test_mujocos_soft_friction_gives_an_error_floor_that_the_study_reports():
    pytest.importorskip("mujoco", reason="MuJoCo is the [bench] extra: pip install '.[bench]'")
    result = study.study(load_scene("stick_slip"), 1.0, ["rk4"], [0.01, 0.005, 0.0025], [],
                         peers=["mujoco"])
    mujoco = result["peers"]["mujoco"]
    rk4 = [r["max_state_error"] for r in series(result, "mujoco RK4")]
    assert rk4[-1] > 0.5 * rk4[0]                    # a finer step no longer helps
    assert mujoco["floor"] == min(r["max_state_error"] for r in result["runs"]
                                  if r["series"].startswith("mujoco"))
    ours = min(r["max_state_error"] for r in series(result, "rk4"))
    assert ours < mujoco["floor"] / 1000
    assert any("frictionloss" in note for note in mujoco["notes"])


def test_mujocos_compliant_limit_is_matched_at_the_joint_inertia_the_arm_has():
    """solref = (-k/I, -c/I) with I = 1/(M⁻¹)ᵢᵢ at the initial pose: MuJoCo's own mass
    matrix there, the motors' armature counted once (scene.arm holds it)."""
    mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the [bench] extra: "
                                                  "pip install '.[bench]'")
    import numpy as np
    from arm_sim_ros.tools.accuracy import mujoco_peer

    k, c = 1e4, 10.0
    scene = load_scene("geared_release").replace(
        payload={"mass": 0.5}, joint_limits={"lower": [-2.0, -2.0], "upper": [2.0, 2.0],
                                             "stiffness": k, "damping": c})
    model, ctrl = mujoco_peer.mujoco_model(scene)
    data = mujoco_peer.mujoco_data(model, scene, ctrl)
    mujoco.mj_forward(model, data)
    mass = np.zeros((2, 2))
    mujoco.mj_fullM(model, data, mass)
    inertia = 1.0 / np.diag(np.linalg.inv(mass))
    assert mujoco_peer.joint_inertia(scene) == pytest.approx(inertia, rel=1e-12)
    assert model.dof_armature == pytest.approx(scene.arm.armature, rel=1e-15)
    for (stiffness, damping), i in zip(model.jnt_solref, inertia):
        assert (stiffness, damping) == pytest.approx((-k / i, -c / i), rel=1e-12)


def test_a_scene_mujoco_cannot_express_is_named_and_the_study_goes_on():
    pytest.importorskip("mujoco", reason="MuJoCo is the [bench] extra: pip install '.[bench]'")
    result = study.study(load_scene("wrong_payload_model"), 0.1, ["rk4"], [0.01], [],
                         peers=["mujoco"])
    assert "controller_model" in result["peers"]["mujoco"]["unavailable"]
    assert [r["series"] for r in result["runs"]] == ["rk4", "rk4, estimate off",
                                                     "rk4 (scene as set)"]


def test_without_mujoco_the_study_says_so_in_one_line_and_carries_on(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "mujoco", None)        # import mujoco fails
    code = cli.main(["accuracy", "--duration", "0.1", "--integrators", "rk4", "--steps", "0.01",
                     "--tolerance-sweep"])
    out = capsys.readouterr().out
    assert code == 0
    said = [line for line in out.splitlines() if "MuJoCo is not installed" in line]
    assert said[0].startswith("peers: ") and "pip install '.[bench]'" in said[0]
    assert "fitted order rk4" in out and "price list" in out


def test_without_matplotlib_a_plot_is_refused_in_one_line_before_any_work(monkeypatch, capsys,
                                                                          tmp_path):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    code = cli.main(["accuracy", "--duration", "0.1", "--plot", str(tmp_path / "p.png")])
    out, err = capsys.readouterr()
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert "--plot needs matplotlib" in err and not (tmp_path / "p.png").exists()


def test_several_scenes_give_one_panel_each_and_a_price_list(tmp_path, capsys):
    out_json, out_png = tmp_path / "r.json", tmp_path / "p.png"
    code = cli.main(["accuracy", "--scenes", "release", "limit_impact", "--duration", "0.2",
                     "--integrators", "rk4", "dopri5", "--steps", "0.01", "--tolerances", "1e-8",
                     "--tolerance-sweep", "1e-6", "--peers", "none", "--repeat", "1",
                     "--json", str(out_json), "--plot", str(out_png)])
    out = capsys.readouterr().out
    assert code == 0
    assert [r["scene"] for r in json.loads(out_json.read_text())["scenes"]] == [
        "release", "limit_impact"]
    assert "release:" in out and "limit_impact:" in out and "ours rk4 + tolerance" in out
    assert out_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_plot_that_cannot_be_written_is_one_line_and_leaves_nothing(tmp_path, capsys,
                                                                      monkeypatch):
    from arm_sim_ros.tools.accuracy import report as accuracy_report

    def full_disk(results, path):
        open(path, "wb").write(b"partial")
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(accuracy_report, "plot", full_disk)
    target = tmp_path / "p.png"
    code = cli.main(["accuracy", "--duration", "0.1", "--integrators", "rk4", "--steps", "0.01",
                     "--peers", "none", "--tolerance-sweep", "--plot", str(target)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "cannot write: No space left on device" in err[0]
    assert not target.exists()


# compliant_limit's stiff stops cost our stepper at h/16 and 1e-11 about 250 s of CPU over 3 s
# in pure Python; its first 0.8 s enters and leaves both joints' stops (shoulder at 0.54 and
# 0.71 s, elbow at 0.78 s) for about 6 s. The whole 3 s is a hunt.
@pytest.mark.parametrize("name, duration", [
    ("stick_slip", 3.0), ("limit_impact", 3.0), ("compliant_limit", 0.8),
    pytest.param("compliant_limit", 3.0, marks=pytest.mark.hunt)])
def test_the_independent_reference_and_our_stepper_at_a_fine_step_agree(name, duration):
    """Two ways to the same motion through its switches: DOP853 events on equations written
    apart, and our event-located rk4 at h/16 held to a tolerance at rounding (5.8e-11 and
    2.5e-10 apart over 3 s, compliant_limit 2.1e-10 over 0.8 s)."""
    from arm_sim_ros.tools.accuracy.independent import Independent
    scene = load_scene(name)
    steps = round(duration / 0.01)
    times = [k * 0.01 for k in range(steps + 1)]
    independent = Independent(scene).states(times)
    fine = Simulator(scene.replace(step_size=0.01 / 16, tolerance=1e-11, max_substeps=20000))
    apart = 0.0
    for k in range(1, steps + 1):
        fine.run(0.01)
        apart = max(apart, max(abs(a - b) for a, b in zip(fine.state[:4], independent[k][:4])))
    assert apart < 1e-6, apart


# What a run costs: every series priced as a user runs it (issue 41).

def same_trajectory(result):
    """Our runs by estimate mode and trajectory (max state error to 10 significant digits)."""
    groups = {}
    for r in result["runs"]:
        if r["estimate"] is not None and isfinite(r["max_state_error"]):
            groups.setdefault((r["estimate"], f"{r['max_state_error']:.9e}"), []).append(r)
    return groups


def test_the_same_trajectory_costs_the_same_in_every_series():
    """damped_release at h = 10 ms takes no sub-step as set nor at tolerances 1e-2 and 1e-3:
    the h sweep, the scene as set and those tolerances are one trajectory, and
    exponential_rk4 without windings is rk4's bits. It was priced at 255 µs per simulated
    second in one series and 1967 in another; now each is Simulator.run over the whole run,
    priced call by call in interleaved rounds, the fastest of its calls: within 1.5x."""
    result = study.study(load_scene("damped_release"), 2.0, ["rk4", "exponential_rk4"],
                         [0.01], [], sweep=[1e-2, 1e-3], repeat=7)
    groups = same_trajectory(result)
    trajectory = f"{series(result, 'rk4')[0]['max_state_error']:.9e}"
    shared = groups[("global", trajectory)]
    assert {r["kind"] for r in shared} == {"method", "as set", "tolerance"}
    assert {r["integrator"] for r in shared} == {"rk4", "exponential_rk4"}
    assert (len(shared), len(groups[("off", trajectory)])) == (7, 2)
    for runs in groups.values():
        costs = [r["cpu_s_per_sim_s"] for r in runs]
        assert max(costs) <= 1.5 * min(costs), [(r["series"], r["tolerance"], c)
                                                for r, c in zip(runs, costs)]


def test_each_integrator_runs_with_and_without_the_estimate_at_the_same_steps():
    """The estimate never touches the step: the two series are one trajectory each step
    size, priced apart."""
    result = study.study(load_scene("release"), 0.5, ["rk4", "midpoint"], [0.01, 0.005], [])
    for name in ("rk4", "midpoint"):
        on, off = series(result, name), series(result, f"{name}, estimate off")
        assert [r["step_size"] for r in on] == [r["step_size"] for r in off] == [0.01, 0.005]
        assert [r["max_state_error"] for r in on] == [r["max_state_error"] for r in off]
        assert {r["estimate"] for r in on} == {"global"} and {r["estimate"] for r in off} == {
            "off"}


def test_every_run_says_its_path_and_estimate_and_the_header_the_path(tmp_path, capsys):
    out_json = tmp_path / "r.json"
    code = cli.main(["accuracy", "--scene", "release", "--duration", "0.2", "--integrators",
                     "rk4", "dopri5", "--steps", "0.01", "--tolerances", "1e-6",
                     "--tolerance-sweep", "1e-6", "--repeat", "1", "--json", str(out_json)])
    out = capsys.readouterr().out
    assert code == 0
    data = json.loads(out_json.read_text())
    path = Simulator(load_scene("release")).path          # compiled where numba is installed
    ours = [r for r in data["runs"] if r["estimate"] is not None]
    assert {(r["integrator"], r["estimate"]) for r in ours if r["kind"] == "method"} == {
        (n, e) for n in ("rk4", "dopri5") for e in ("global", "off")}
    assert all(r["path"] == (path if r["integrator"] == "rk4" else "python") for r in ours)
    assert data["path"] == path and f"Simulator.run over the whole run, path {path}" in out
    assert (data["node"]["kind"], data["node"]["path"]) == ("node", path)
    theirs = [r for r in data["runs"] if r["estimate"] is None]
    assert {(r["kind"], r["path"]) for r in theirs} <= {("mujoco", MJ_STEP),
                                                         ("mujoco rollout", ROLLOUT)}
    if theirs:
        assert len({r["path"] for r in theirs}) == 2 and "mujoco.rollout" in out


def test_the_nodes_path_is_priced_beside_the_scene_as_set():
    """The node steps through Simulator.step, a Python call per step: the scene as set's
    trajectory at its own price, one line of the price list (not a run: the same
    trajectory at another price would break the rule above)."""
    from arm_sim_ros.tools.accuracy import report
    result = study.study(load_scene("damped_release"), 0.5, ["rk4"], [0.01], [])
    (as_set,), node = series(result, "rk4 (scene as set)"), result["node"]
    assert (node["max_state_error"], node["substeps"]) == (as_set["max_state_error"],
                                                           as_set["substeps"])
    assert node["series"] == "rk4 (scene as set, Simulator.step)"
    assert node["kind"] not in {r["kind"] for r in result["runs"]}
    line = next(s for s in report.price_list([result], study.TARGET).splitlines()
                if s.startswith("  ours as set, the node's path"))
    assert f"{node['cpu_s_per_sim_s'] * 1e6:.0f} µs/s" in line


@pytest.mark.parametrize("name, integrator, restarts", [("damped_release", "RK4", False),
                                                        ("compliant_limit", "Euler", True)])
def test_mujocos_rollout_takes_the_steps_mj_step_takes_even_where_it_restarts(name, integrator,
                                                                              restarts):
    pytest.importorskip("mujoco", reason="MuJoCo is the [bench] extra: pip install '.[bench]'")
    from arm_sim_ros.tools.accuracy import mujoco_peer
    scene = load_scene(name)
    stepped = mujoco_peer.Runner(scene, integrator).run(200, 10)
    rolled = mujoco_peer.Rollout(scene, integrator).run(200, 10)
    assert rolled == stepped and len(rolled) == 21
    assert any(isinf(s[0]) for s in rolled) == restarts     # unstable: infinitely wrong


def test_prices_are_taken_in_rounds_over_every_run_in_turn(monkeypatch):
    from arm_sim_ros.tools.accuracy import timing
    monkeypatch.setattr(timing, "ROUND_CPU_S", 0.0)
    calls = []
    priced = [timing.Priced(study.Run(n, 0.01, None, 0.0, 0.0, 0.0),
                            lambda n=n: calls.append(n), lambda n=n: calls.append(n.upper()))
              for n in "ab"]
    timing.price(priced, 3, 2.0)
    assert "".join(calls) == "AaBb" * 3           # prepared untimed, then run, in turn
    assert [p.run.cpu_s_per_sim_s for p in priced] == [min(p.calls) / 2.0 for p in priced]
    assert [len(p.calls) for p in priced] == [3, 3]


def test_a_short_run_is_called_in_turn_with_the_others_not_back_to_back(monkeypatch):
    """A run shorter than its share of a round is called again, each call in turn with the
    runs still short of theirs (a slow spell of the machine falls on all alike), with the
    garbage collector off; its price is its fastest call."""
    import gc
    from arm_sim_ros.tools.accuracy import timing
    clock, calls = [0.0], []
    monkeypatch.setattr(timing.time, "process_time", lambda: clock[0])

    def go(name, costs):
        calls.append((name, gc.isenabled()))
        clock[0] += costs[sum(n == name for n, _ in calls) - 1]
    priced = [timing.Priced(study.Run("a", 0.01, None, 0.0, 0.0, 0.0),
                            lambda: go("a", [0.004, 0.003, 0.002, 0.005])),
              timing.Priced(study.Run("b", 0.01, None, 0.0, 0.0, 0.0), lambda: go("b", [0.02]))]
    timing.price(priced, 1, 2.0)
    assert [n for n, _ in calls] == ["a", "b", "a", "a", "a"]   # 4 + 3 + 2 + 5 ms >= 10
    assert not any(collecting for _, collecting in calls) and gc.isenabled()
    assert [p.run.cpu_s_per_sim_s for p in priced] == pytest.approx([0.001, 0.01])
