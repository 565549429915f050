"""Issues 14 and 22: every step's local error estimate, the global error estimate, and the
tolerance.

The global estimate (`accumulated_error`: the largest distance of the motion from its
shadow, physics/trust/accuracy.py) is compared with the true error (the largest |q, qd|
difference at any step) against scipy's DOP853 at rtol = atol = 1e-13; for scenes that
switch modes (friction, limits: events.py) against DOP853 with the switches as terminal
events and restarts on equations written apart (tools/accuracy/independent.py); where that does
not reach (motors, clamps), the same event-located stepper at h/16 held to a tolerance at
rounding (an order of accuracy and 16^4 closer).

The rule, on every preset, every integrator and random scenes, with no exceptions: the
estimate is within a factor of 10 of the true error; where the true error is rounding
(< 1e-10) the estimate is rounding too; where the run says it lost the motion (global
error beyond 1 rad: a step far too coarse, or chaos), the estimate says at least that
much and so does the true error.
"""
from math import ceil, isnan
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.integrate import solve_ivp

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from arm_sim_ros.physics.trust.accuracy import DEFAULT_TOLERANCE
from arm_sim_ros.physics.trust.shadow import LOST, MAX_EVERY
from arm_sim_ros.physics.scene import Scene, load_scene, preset_names
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.tools.accuracy.independent import Independent, covers
from physics.test_friction_limits import STOPPING_AT_ONE_INSTANT

FINE = 16   # reference sub-division for switching scenes (and a tolerance of 1e-11)


def arm(lengths, masses, h=0.02, **kw):
    """Rods of these lengths and masses (COM at the middle, I = m l^2 / 12), under a
    constant torque: a motion damping makes contract."""
    return Scene(link_lengths=lengths, link_masses=masses, com_distances=tuple(
        length / 2 for length in lengths), com_inertias=tuple(
        m * length * length / 12 for m, length in zip(masses, lengths)), step_size=h,
        policy="constant", **kw)


def spin(h, **kw):
    """100 rad/s about the shoulder, elbow bent 0.5 rad, gravity off."""
    values = dict(initial_positions=(0.0, 0.5), initial_velocities=(100.0, 0.0), gravity=0.0,
                  step_size=h)
    return Scene(**(values | kw))


def reference(scene, sim, steps):
    h = scene.step_size
    if sim.switching is None:
        f, width = sim.dynamics.function, 4 + len(sim.extra)
        times = [k * h for k in range(steps + 1)]
        solution = solve_ivp(lambda t, y: (y[2], y[3], *f(*y[:width])), (0.0, times[-1]),
                             list(sim.state), method="DOP853", t_eval=times, rtol=1e-13,
                             atol=1e-13)
        return np.asarray(solution.y).T
    if covers(scene) is None:          # friction and limits, on equations written apart
        independent = Independent(scene)
        states = independent.states([k * h for k in range(steps + 1)])
        return Switched(states, {ceil(t / h - 1e-9) for t in independent.switch_times})
    fine = Simulator(scene.replace(step_size=h / FINE, tolerance=1e-11, max_substeps=20000))
    states = [sim.state]
    for _ in range(steps):
        for _ in range(FINE):
            fine.step()
        states.append(fine.state)
    return states


class Switched(list):
    """Reference states, and the steps in which the reference switched."""

    def __init__(self, states, steps):
        super().__init__(states)
        self.steps = steps


def errors(scene, duration):
    """(the global estimate, the largest true error, the simulator after the run). In a
    step in which either switched, velocities are not compared: a switch a hair apart in
    time makes a jump there (the acceleration's, an impact's), not an error (as the
    estimate, shadow.py)."""
    sim = Simulator(scene)
    steps = scene.steps_for(duration)
    expected = reference(scene, sim, steps)
    switched = getattr(expected, "steps", set())
    true = 0.0
    for k in range(1, steps + 1):
        before = sum(sim.switch_events.values())
        sim.step()
        jump = k in switched or sum(sim.switch_events.values()) != before
        true = max(true, max(abs(a - b) for a, b in zip(sim.state[:2 if jump else 4],
                                                         expected[k][:2 if jump else 4])))
    return sim.accumulated_error, true, sim


def ratio(scene, duration):
    """(global estimate / the largest true error, the largest true error)."""
    estimate, true, _ = errors(scene, duration)
    return estimate / true, true


ROUNDING = 1e-10


def assert_honest(scene, duration, name=""):
    estimate, true, sim = errors(scene, duration)
    if true <= ROUNDING:
        assert estimate <= 10 * ROUNDING, (name, estimate, true)
    elif sim.accuracy.shadow.lost:
        assert estimate >= LOST and true >= 0.1 * LOST, (name, estimate, true)
        assert any("no longer follows" in e.message for e in sim.events), name
    else:
        assert 0.1 <= estimate / true <= 10.0, (name, estimate / true, true)


CASES = {name: (load_scene(name), 2.0) for name in preset_names()}
CASES |= {
    "spin_1ms": (spin(0.001), 1.0),
    "spin_10ms": (spin(0.01), 1.0),
    "spin_1ms_estimate_only": (spin(0.001, tolerance=0.0), 1.0),
    "spin_10ms_estimate_only": (spin(0.01, tolerance=0.0), 1.0),
    "spin_damped": (spin(0.001, damping=0.5), 1.0),
    # the elbow leaves a stiff compliant stop the shoulder is still in: each contact
    # sub-step's error carried through the rest of the step (it was 10.02x summed)
    "compliant_stop_exit": (Scene(
        initial_velocities=(2.5, 0.0), gravity=0.0, springs={
            "stiffness": (1.5, 1.0), "rest_positions": (0.0, 0.0)}, joint_limits={
            "lower": (-1.3, -1.8), "upper": (1.3, 1.8), "stiffness": 8624.0, "damping": 1.0},
        tolerance=0.0, step_size=0.005), 1.0),
    # joint 1's velocity goes through zero and back within 4 ms (a stick of 1.7 ms): the
    # reference's DOP853 stepped over it until its steps were bounded (independent.MAX_STEP)
    "through_zero_and_back": (Scene(
        initial_velocities=(3.80078125, -1.9140625), gravity=0.0, springs={
            "stiffness": (80.75, 55.3125), "rest_positions": (0.0, 0.0)}, payload={"mass": 0.518},
        friction={"coulomb": (0.5, 0.05), "static": (0.5, 0.05)}, tolerance=0.0,
        step_size=0.001), 1.0),
    # the elbow's local error turns every 4 steps: checked every 2 steps, it was seen near
    # its zeros only (0.074x); checks now come every step where it moves that fast
    "local_error_turning_within_4_steps": (Scene(
        initial_positions=(0.0, 1.109375), gravity=0.0, springs={
            "stiffness": (1.0, 38.0), "rest_positions": (0.0, 0.0)}, payload={"mass": 1.0},
        tolerance=1e-7, step_size=0.01), 1.0),
    # the shadow's twin lands 1e-15 past the elbow's stop, drifting back: on that stop
    # (it was put on the other one and read "lost" where the true error was 4.5e-8)
    "plastic_stop_past_by_rounding": (Scene(
        initial_positions=(1.0, 0.3784167202976225), initial_velocities=(
            3.5195579268223973, -3.2737318517314673), gravity=0.0, damping=0.1348,
        joint_limits={"lower": (-1.3, -1.8), "upper": (1.3, 1.8), "restitution": 0.0},
        tolerance=0.0, step_size=0.005), 1.0),
    # the local error decays within 4 steps of the shoulder leaving a stiff stop: the
    # schedule starts afresh after a switch (it went on from its pre-contact spacing, and
    # the shadow, 30x the motion's error off the truth, entered the next stop late: 22x)
    "schedule_afresh_after_a_stop": (Scene(
        initial_positions=(1.0, 0.375), initial_velocities=(3.5234375, -3.28125), gravity=0.0,
        damping=0.1328125, joint_limits={"lower": (-1.3, -1.8), "upper": (1.3, 1.8),
                                         "stiffness": 39952.0, "damping": 20.0},
        tolerance=0.0, step_size=0.005), 1.0),
    # both joints stop at t = 0 (rest to rounding): settled together, as the reference does
    "joints_stopping_at_one_instant": (STOPPING_AT_ONE_INSTANT, 1.0),
    # contracting motions (issue 39): a damped arm that is not the default one settles
    # under a constant torque at h = 0.02. The first step, from rest, asks for 17 sub-steps
    # and the controller for 9: the error predicted at 9 by the n^-p law was 700x the error
    # measured there (a stiff transient sets it), and the shadow carried it (16.1x); a new
    # count's error is measured at the next step now (1.0x)
    "damped_constant_torque_at_a_new_count": (arm(
        (1.5, 0.47), (0.96, 1.26), damping=5.0, gravity=0.0, constant_torque=(-9.29, -2.81)),
        5.0),
    # ... and plain steps at 99 % of RK4's stability limit, where a step keeps 95 % of a fast
    # mode the flow keeps 6 % of (9.6x; 9.7x with each new count measured; 1.0x with the
    # shadow's local error measured where the shadow is: Accuracy.at_shadow)
    "damped_constant_torque_near_the_stability_limit": (arm(
        (0.53, 0.93), (1.71, 0.54), damping=5.0, constant_torque=(1.23, 1.57)), 5.0),
    # split steps (issue 47): checked against ceil(n/2) coarser sub-steps alone, a step's
    # estimate carried the next error term twice over (5-30 % off on these steps); its bias
    # did not cancel over a turn as the true errors do: 11.5x over 5 s at 10 ms, and 0.014x
    # at 1 ms with the elbow turning too. Against two coarser counts (many sub-steps) or
    # finer ones: 1.1x and 0.33x
    "spin_10ms_for_5_s": (spin(0.01), 5.0),
    "spin_1ms_elbow_turning_for_5_s": (spin(0.001, initial_velocities=(100.0, -60.0)), 5.0),
}
CASES |= {f"release_{integrator}_tolerance_{tolerance:g}": (
    load_scene("release").replace(integrator=integrator, tolerance=tolerance), 2.0)
    for integrator in ("rk38", "midpoint", "euler", "semi_implicit_euler", "dopri5")
    for tolerance in (0.0, DEFAULT_TOLERANCE)}


@pytest.mark.parametrize("name", list(CASES))
def test_the_global_estimate_is_within_a_factor_of_10_of_the_true_error(name):
    scene, duration = CASES[name]
    assert_honest(scene, duration, name)


def test_near_the_stability_limit_the_shadow_measures_its_own_local_error(monkeypatch):
    """A step that does not decay as the flow does makes a local error that is mostly the
    part of its error it fails to damp; the shadow's step propagates that part again, so
    the motion's local error cannot stand for the shadow's: measured where the shadow is,
    the estimate is 1.0x the true error (9.7x with the motion's)."""
    scene, duration = CASES["damped_constant_torque_near_the_stability_limit"]
    estimate, true, sim = errors(scene, duration)
    assert sim.accuracy.substeps < sim.accuracy.stiff_below       # plain steps, stiff
    assert estimate / true < 2.0, estimate / true


@st.composite
def contracting_scenes(draw):
    """A damped arm that is not the default one, under a constant torque, at coarse steps:
    the motion settles and its error contracts (issue 39's case was 30x)."""
    lengths = (draw(st.floats(0.3, 1.5)), draw(st.floats(0.3, 1.5)))
    masses = (draw(st.floats(0.3, 3.0)), draw(st.floats(0.3, 3.0)))
    torque = tuple(draw(st.sampled_from([-1.0, 1.0])) * draw(st.floats(0.5, 10.0))
                   for _ in range(2))          # (a torque of 1e-53 moves it by rounding)
    return arm(lengths, masses, h=draw(st.sampled_from([0.005, 0.01, 0.02])),
               damping=draw(st.floats(0.5, 10.0)), gravity=draw(st.sampled_from([0.0, 9.81])),
               tolerance=draw(st.sampled_from([0.0, DEFAULT_TOLERANCE, 1e-7])),
               constant_torque=torque)


@settings(max_examples=6, deadline=None, derandomize=True, database=None,
          suppress_health_check=list(HealthCheck))
@given(contracting_scenes())
def test_the_global_estimate_is_honest_on_contracting_motions(scene):
    assert_honest(scene, 5.0, scene)


@pytest.mark.hunt
@settings(max_examples=300, deadline=None, derandomize=True, database=None,
          suppress_health_check=list(HealthCheck))
@given(contracting_scenes())
def test_hunt_the_global_estimate_on_contracting_motions(scene):
    assert_honest(scene, 5.0, scene)


JTC = yaml.safe_load((Path(__file__).resolve().parents[2] / "config" /
                      "ros2_controllers.yaml").read_text())["effort_trajectory_controller"]


def held_by_a_controller_outside(scene, seconds, rate=100.0):
    """The shipped effort JTC's PID (config/ros2_controllers.yaml: p e + d ė + i ∫e, its
    integral clamped, the effort within ±50 N m) at `rate` around the arm, each answer
    through set_command as the node hands a command on: a smooth step to (0.8, -0.4) over
    2 s, held, and back every 10 s. The simulator and its state at each answer."""
    sim, gains = Simulator(scene), JTC["ros__parameters"]["gains"]
    ticks, integral, states = round(1.0 / (rate * scene.step_size)), [0.0, 0.0], []
    for k in range(round(seconds * rate)):
        t = k / rate % 20.0
        a, b = ((0.3, 0.6), (0.8, -0.4))[::1 if t < 10.0 else -1]
        s = min(t % 10.0 / 2.0, 1.0)
        target = [x + (y - x) * (3 * s * s - 2 * s ** 3) for x, y in zip(a, b)]
        rate_of = [(y - x) * (6 * s - 6 * s * s) / 2.0 for x, y in zip(a, b)]
        effort = []
        for j, g in enumerate(gains.values()):
            error = target[j] - sim.state[j]
            integral[j] += error / rate
            held = min(max(g["i"] * integral[j], g["i_clamp_min"]), g["i_clamp_max"])
            effort.append(min(50.0, max(-50.0, g["p"] * error + held
                                        + g["d"] * (rate_of[j] - sim.state[2 + j]))))
        sim.set_command(*effort)
        for _ in range(ticks):
            sim.step()
        states.append(sim.state[:4])
    return sim, states


HELD = load_scene("servo_hold").replace(servo=None, effort_limits=None,
                                        policy="command_gravity_compensation")


def test_an_arm_a_controller_outside_holds_keeps_an_honest_estimate():
    """Issue 40: an effort JTC holding the arm (gravity fed forward: a neutral arm) made the
    node say at t = 458 s that the run had lost its motion. The shadow took each command as
    a torque given for ever, not as an answer to the state the controller read: at a
    velocity no controller answered it drifted, and each goal amplified the drift (10x per
    10 s here, the error of the loop closed around h/16 at 1.7e-10; 28x at 20 s). It takes
    the motion's velocity at each new torque now: 0.42x."""
    scene = HELD.replace(step_size=0.01)
    (sim, states), (_, reference) = (held_by_a_controller_outside(at, 20.0) for at in (
        scene, scene.replace(step_size=0.01 / FINE, tolerance=1e-11, max_substeps=20000)))
    true = max(max(abs(a - b) for a, b in zip(x, y)) for x, y in zip(states, reference))
    assert not sim.accuracy.shadow.lost
    assert 0.1 <= sim.accumulated_error / true <= 10.0, (sim.accumulated_error, true)


@pytest.mark.hunt
def test_hunt_an_arm_held_by_a_controller_outside_for_500_s_is_never_lost():
    """The shipped scene and rate, as long as the run that said it was lost at 458 s: the
    estimate stays at rounding (so does the true error: 1.5e-13 over the first 40 s)."""
    sim, _ = held_by_a_controller_outside(HELD, 500.0)
    assert not sim.accuracy.shadow.lost and sim.accumulated_error < 1e-10


@st.composite
def random_scenes(draw):
    """Effects, step, initial state and tolerance drawn at random."""
    keys = {"gravity": draw(st.sampled_from([0.0, 9.81])),
            "step_size": draw(st.sampled_from([0.001, 0.002, 0.005, 0.01])),
            "tolerance": draw(st.sampled_from([0.0, DEFAULT_TOLERANCE, 1e-7])),
            "initial_positions": (draw(st.floats(-1.0, 1.0)), draw(st.floats(-1.5, 1.5))),
            "initial_velocities": (draw(st.floats(-4.0, 4.0)), draw(st.floats(-4.0, 4.0)))}
    if draw(st.booleans()):
        keys["damping"] = draw(st.floats(0.05, 3.0))
    if draw(st.booleans()):
        keys["springs"] = {"stiffness": (draw(st.floats(1.0, 100.0)),
                                         draw(st.floats(1.0, 100.0)))}
    if draw(st.booleans()):
        keys["payload"] = {"mass": draw(st.floats(0.0, 2.0))}
    if draw(st.booleans()):
        coulomb = (draw(st.floats(0.05, 2.0)), draw(st.floats(0.05, 1.0)))
        keys["friction"] = {"coulomb": coulomb,
                            "static": tuple(c * draw(st.floats(1.0, 1.5)) for c in coulomb)}
    limits = draw(st.sampled_from([None, "hard", "compliant"]))
    if limits:
        keys["joint_limits"] = {"lower": (-1.3, -1.8), "upper": (1.3, 1.8)} | (
            {"restitution": draw(st.floats(0.0, 0.9))} if limits == "hard" else
            {"stiffness": draw(st.floats(1e3, 1e5)), "damping": draw(st.floats(0.0, 30.0))})
    return Scene(**keys)


@settings(max_examples=12, deadline=None, derandomize=True, database=None,
          suppress_health_check=list(HealthCheck))
@given(random_scenes())
def test_the_global_estimate_is_honest_on_random_scenes(scene):
    assert_honest(scene, 1.0, scene)


@pytest.mark.parametrize("h", [0.001, 0.01])
def test_the_default_tolerance_keeps_a_fast_spin_honest(h):
    """A relative energy drift of 6.9e-7 at 1 ms and 2.9e-7 at 10 ms over 5 s (the count
    follows the error both ways: it no longer keeps the peak's count to the end)."""
    sim = Simulator(spin(h))
    assert sim.scene.tolerance == DEFAULT_TOLERANCE > 0
    start, drift = sim.energy(sim.state), [0.0]
    sim.run(5.0, lambda s: drift.__setitem__(0, max(drift[0], abs(s.energy(s.state) - start))))
    assert drift[0] / start < 2e-6
    assert sim.substeps_taken > 0 and any(e.kind == "substeps" for e in sim.events)
    plain = Simulator(spin(h, tolerance=0.0))
    plain.run(0.5)
    assert plain.substeps_taken == 0 and plain.error_estimate > 0


@pytest.mark.parametrize("name,h,duration", [
    ("shoulder_torque_no_gravity", 0.01, 0.5), ("moving_gravity_compensation", 0.01, 1.0),
    ("downward_equilibrium", 0.01, 2.0), ("damped_release", 0.01, 2.0)])
def test_where_plain_steps_meet_the_default_tolerance_they_stay_plain(name, h, duration):
    runs = []
    for tolerance in (0.0, DEFAULT_TOLERANCE):
        sim = Simulator(load_scene(name).replace(step_size=h, tolerance=tolerance))
        states = []
        sim.run(duration, lambda s: states.append(s.state))
        runs.append(states)
        assert sim.substeps_taken == 0
    assert runs[0] == runs[1]


@pytest.mark.parametrize("name, steps", [("gravity_compensation_at_rest", 200),
                                         ("downward_equilibrium", 200),
                                         ("motor_windings_hold", 2000)])
def test_where_the_local_error_is_rounding_checks_come_every_max_every_steps(name, steps):
    """A check costs two steps' evaluations. Rounding moves as fast as its size, so it is
    measured against ROUNDING: an arm held at rest (the windings' hold once its current has
    settled) is checked every MAX_EVERY steps, not every MIN_EVERY (the estimate stays
    honest: the factor-of-10 rule above)."""
    sim = Simulator(load_scene(name))
    checks = set()          # each check moves `since` to the step after it
    sim.run(steps * sim.step_size, lambda s: checks.add(s.accuracy.since))
    assert len(checks) <= 2 * steps // MAX_EVERY + 5 and sim.accuracy.every == MAX_EVERY


def test_a_motion_lost_in_a_plain_step_is_said_in_that_step():
    """It was said at the next check only (a run that lost it in its last steps ended
    without a word): a shadow corrected by a local error of 5 rad loses the motion in the
    plain step after a check."""
    sim = Simulator(load_scene("release"))
    while not sim.accuracy.due > sim.steps + 1:     # a check next, and a plain step after
        sim.step()
    sim.step()
    assert sim.steps < sim.accuracy.due and not sim.accuracy.shadow.lost
    sim.accuracy.shadow.local = [5.0, 0.0, 0.0, 0.0]
    sim.step()
    assert sim.accuracy.shadow.lost
    said = [e.message for e in sim.events if "no longer follows" in e.message]
    # release holds the default tolerance: an "unpredictable" event ("past t = ..."), at the step
    assert len(said) == 1 and f" t = {sim.steps * sim.scene.step_size:.6g} s" in said[0]


def test_a_new_command_is_checked_at_the_next_step():
    """An arm at rest is checked every MAX_EVERY steps; a command (the node's torque topic)
    moves the local error at once, so the step after it is checked, and the estimate of
    the motion it starts is honest (against the same steps at h/16, tolerance 1e-11)."""
    scene = load_scene("gravity_compensation_at_rest").replace(
        policy="command_gravity_compensation")
    runs = []
    for at in (scene, scene.replace(step_size=scene.step_size / FINE, tolerance=1e-11,
                                    max_substeps=20000)):
        sim, states, checks = Simulator(at), [], set()
        sim.run(1.0)
        assert sim.accuracy.every == MAX_EVERY
        sim.set_command(6.0, -3.0)
        sim.run(0.5, lambda s: (states.append(s.state[:4]), checks.add(s.accuracy.since)))
        runs.append((sim, states, checks))
    (sim, states, checks), (_, fine, _) = runs
    assert sim.steps + 1 - len(states) in checks          # the step after the command
    true = max(max(abs(a - b) for a, b in zip(state, fine[FINE * (i + 1) - 1]))
               for i, state in enumerate(states))
    assert 0.1 <= sim.accumulated_error / true <= 10.0, (sim.accumulated_error, true)


def test_the_default_tolerance_splits_release_where_the_elbow_whips():
    """Plain RK4 at 10 ms makes up to ~1e-3 rad per s there, 20x the default tolerance:
    the steps are split where it does and given back after."""
    sim = Simulator(load_scene("release"))
    counts = []
    sim.run(4.0, lambda s: counts.append(s.accuracy.substeps))
    assert counts[0] == 1 and max(counts) > 1 and min(counts[len(counts) // 2:]) == 1


def test_stiff_modes_that_decay_within_the_step_do_not_split_it():
    """The estimate is the step's error at its end (2n half sub-steps against n), so a
    stiff damping's transient, which the stability plan's sub-steps damp out within the
    step, asks for nothing more; a mildly stiff one that the step does not damp out does."""
    moving = load_scene("damped_release").replace(initial_positions=(0.3, 1.2),
                                                  initial_velocities=(4.0, -6.0))
    for damping, h in ((500.0, 0.05), (1e4, 0.001)):
        sim = Simulator(moving.replace(damping=damping, step_size=h))
        sim.run(0.5)
        assert sim.substeps > 1 and sim.substeps_taken == sim.steps * sim.substeps
    sim = Simulator(moving.replace(damping=50.0))
    sim.run(0.5)
    assert sim.substeps_taken > sim.steps * sim.substeps


def test_every_integrator_and_switching_scene_reports_an_estimate():
    for integrator in ("rk4", "rk38", "midpoint", "euler", "semi_implicit_euler", "dopri5"):
        sim = Simulator(load_scene("release").replace(integrator=integrator))
        sim.run(0.5)
        assert sim.error_estimate > 0 and sim.accumulated_error > 0
        sim.reset()
        assert sim.accumulated_error == 0.0
    for name in ("stick_slip", "limit_impact", "compliant_limit", "effort_limited_hold"):
        sim = Simulator(load_scene(name))
        sim.run(0.5)
        assert sim.error_estimate >= 0 and sim.accumulated_error > 0, name
    refused = Simulator(load_scene("release").replace(damping=1e9))   # the plan refuses
    assert isnan(refused.error_estimate) and isnan(refused.accumulated_error)


@pytest.mark.parametrize("name", ["compliant_limit", "stick_slip", "geared_arm"])
def test_substeps_taken_counts_the_sub_steps_the_switching_stepper_adds(name):
    """events.py splits steps itself: while a compliant limit is engaged (substeps_for) and
    the rest of a step after a located switch. A step with a switch in it is a split step
    and counts every sub-step it took; other steps count the plan's (0 for plain steps)."""
    sim = Simulator(load_scene(name).replace(tolerance=0.0))
    planned = sim.substeps if sim.substeps > 1 else 0
    taken = switches = split = 0
    for _ in range(sim.scene.steps_for(2.0)):
        mode = sim.switching.mode          # None until the first step finds it
        engaged = mode is not None and bool(mode[2] or mode[3])
        sim.step()
        grown, taken = sim.substeps_taken - taken, sim.substeps_taken
        switched, switches = sum(sim.switch_events.values()) > switches, sum(
            sim.switch_events.values())
        if switched or engaged:
            assert grown >= max(2, planned + 1), (name, sim.steps, grown)
            split += 1
        else:
            assert grown == planned, (name, sim.steps, grown)
    assert split > 0 and taken > planned * sim.steps


@pytest.mark.parametrize("name", ["release", "stick_slip", "compliant_limit", "limit_impact",
                                  "payload_release", "geared_arm", "moving_frozen_gravity"])
def test_the_accumulated_error_never_goes_down(name):
    """A sum of estimates >= 0: steps between checks count at half the latest estimate, the
    least the mean the next check books them at can be."""
    sim = Simulator(load_scene(name))
    before = sim.accumulated_error
    for _ in range(sim.scene.steps_for(2.0)):
        sim.step()
        assert sim.accumulated_error >= before, (name, sim.steps, before, sim.accumulated_error)
        before = sim.accumulated_error
    assert before > 0.0


def test_a_negative_tolerance_is_refused():
    from arm_sim_ros.physics.scene import SceneError
    with pytest.raises(SceneError, match="tolerance"):
        load_scene("release").replace(tolerance=-1.0)


def evaluations_of(scene, duration):
    """(the final state, the right-hand side's evaluations) of a run of `scene`."""
    sim, count = Simulator(scene), [0]
    rhs = sim._rhs

    def counted(*state):
        count[0] += 1
        return rhs(*state)
    sim._rhs = counted
    sim.run(duration)
    return sim.state, count[0]


def test_dopri5s_estimate_does_the_work_of_its_trajectory_whatever_the_tolerances():
    """geared_release at h = 10 ms takes the same steps at rtol 1e-4 and 1e-6 (its pair never
    splits one), so `arm-sim accuracy` prices them as one trajectory. The estimate doubles
    the sub-steps the pair took, so it does the same work for both; measured against the
    same step at rtol / 1000, rtol 1e-8 cost 1.73x rtol 1e-4 in the study."""
    runs = [evaluations_of(load_scene("geared_release").replace(
        integrator="dopri5", rtol=rtol, tolerance=0.0, step_size=0.01), 2.0)
        for rtol in (1e-4, 1e-6)]
    (loose, loose_work), (tight, tight_work) = runs
    assert loose == tight
    assert loose_work == tight_work
