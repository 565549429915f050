"""Hard cases: stiff damping, fast spins, long runs, extreme arms, steps that would leave the
finite numbers. The property-based sweep over d x step lives in test_properties.py."""
import itertools
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from arm_sim_ros.physics import model
from arm_sim_ros.physics.stepping.integrators import RK4, ButcherTableau, compile_step
from arm_sim_ros.physics.scene import Scene, SceneError, load_scene
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.physics.stepping.stability import (RK4_REAL_LIMIT, SUBSTEP_FRACTION,
                                                    inverse_mass_eigenvalue,
                                                    real_stability_limit, stability_polynomial,
                                                    stiffness, worst_stiffness)

DAMPED = load_scene("damped_release")
RODS = DAMPED.arm
MOVING = DAMPED.replace(initial_positions=(0.3, 1.2), initial_velocities=(4.0, -6.0))


def raw_rk4_run(scene, steps):
    """The classical RK4 loop with no plan and no guard: what Simulator.step used to be."""
    sim = Simulator(scene)
    step, y = compile_step(RK4, len(sim.channels)), sim.state
    out = [y]
    for _ in range(steps):
        y = step(sim._rhs, y, scene.step_size)
        out.append(y)
    return out


def sim_run(scene, steps):
    """The stability plan alone: tolerance 0 (the default tolerance, accuracy.py, also
    splits a step whose error estimate asks for it: test_error_estimate.py)."""
    sim = Simulator(scene.replace(tolerance=0.0))
    out = [sim.state]
    for _ in range(steps):
        sim.step()
        out.append(sim.state)
    return sim, out


def energies(scene, states):
    arm = scene.arm
    return np.array([model.kinetic_energy(arm, y[:2], y[2:4])
                     + model.potential_energy(arm, y[:2], scene.gravity) for y in states])


# --- the bound ---------------------------------------------------------------------------------

def test_rk4_real_axis_limit_is_where_the_amplification_returns_to_one():
    x = RK4_REAL_LIMIT
    assert x == pytest.approx(2.785293563405, abs=1e-11)
    assert x ** 3 - 4 * x ** 2 + 12 * x - 24 == pytest.approx(0.0, abs=1e-12)
    assert [float(c) for c in stability_polynomial(RK4)] == pytest.approx([1, 1, 1 / 2, 1 / 6, 1 / 24])


def test_forward_euler_limit_is_two():
    euler = ButcherTableau("euler", c=(0,), a=((),), b=(1,), order=1)
    assert real_stability_limit(euler) == pytest.approx(2.0, abs=1e-12)


def test_rods_stiffness_is_the_issues_figure():
    assert stiffness(RODS, 0.0) == pytest.approx(15.0877, abs=1e-4)
    assert worst_stiffness(RODS) == stiffness(RODS, 0.0)
    # d at the limit for h = 0.01, as the issue quotes it
    assert RK4_REAL_LIMIT / (0.01 * worst_stiffness(RODS)) == pytest.approx(18.46, abs=0.01)


@pytest.mark.parametrize("lengths,masses,coms,inertias", [
    ((1, 1), (1, 1), (0.5, 0.5), (1 / 12, 1 / 12)),
    ((0.3, 2.0), (5.0, 0.01), (0.1, 1.9), (0.0, 0.0)),
    ((2.0, 0.1), (0.2, 30.0), (1.5, -0.05), (0.4, 0.001)),
    ((1.0, 1.0), (1.0, 1.0), (1.0, 1.0), (0.0, 0.0)),          # point masses (Tedrake)
])
def test_worst_stiffness_bounds_every_elbow_angle(lengths, masses, coms, inertias):
    arm = model.ArmParameters(lengths, masses, coms, inertias)
    grid = max(stiffness(arm, q2) for q2 in np.linspace(-4 * math.pi, 4 * math.pi, 4001))
    assert worst_stiffness(arm) >= grid * (1 - 1e-12)
    assert worst_stiffness(arm) == pytest.approx(grid, rel=1e-9)
    # ... and is lambda_max(M^-1) by linear algebra
    m11, m12, m22 = model.mass_matrix(arm, (0.0, 0.0))
    assert stiffness(arm, 0.0) == pytest.approx(
        max(np.linalg.eigvalsh(np.linalg.inv([[m11, m12], [m12, m22]]))), rel=1e-12)


def test_the_inverse_mass_eigenvalue_of_arrays_is_each_arms():
    """batch.py asks it of every arm at once (numpy's hypot): the same numbers."""
    arms = [model.ArmParameters(*p) for p in (((1, 1), (1, 1), (0.5, 0.5), (1 / 12, 1 / 12)),
                                               ((0.3, 2.0), (5.0, 0.01), (0.1, 1.9), (0.0, 0.0)))]
    for q2 in (0.0, math.pi):
        m11, m12, m22 = (np.array(m) for m in zip(*(model.mass_matrix(a, (0.0, q2)) for a in arms)))
        assert list(inverse_mass_eigenvalue(m11, m12, m22, np.hypot)) == pytest.approx(
            [stiffness(a, q2) for a in arms], rel=1e-15)


# --- bit-for-bit where RK4 is stable -----------------------------------------------------------

@pytest.mark.parametrize("scene_name", ["release", "damped_release", "shoulder_torque_no_gravity",
                                        "moving_frozen_gravity", "moving_gravity_compensation"])
def test_presets_are_plain_rk4_bit_for_bit(scene_name):
    scene = load_scene(scene_name)
    sim, out = sim_run(scene, 200)
    assert sim.substeps == 1 and sim.substeps_taken == 0 and not sim.events
    assert out == raw_rk4_run(scene, 200)


def test_just_below_the_limit_is_still_plain_rk4():
    h = 0.01
    scene = MOVING.replace(step_size=h, damping=0.999 * RK4_REAL_LIMIT / (h * worst_stiffness(RODS)))
    sim, out = sim_run(scene, 100)
    assert sim.substeps == 1
    assert out == raw_rk4_run(scene, 100)


def test_just_above_the_limit_plain_rk4_gains_energy_and_the_simulator_does_not():
    """The issue's failure: just past d h lambda = 2.785 RK4 returns finite, energy-gaining states."""
    h = 0.01
    scene = DAMPED.replace(step_size=h, damping=1.2 * RK4_REAL_LIMIT / (h * worst_stiffness(RODS)))
    raw = raw_rk4_run(scene, 200)
    raw_energy = energies(scene, raw)
    assert np.all(np.isfinite(raw_energy[:60]))
    assert raw_energy[:60].max() > raw_energy[0] + 1.0         # finite, and wrong

    sim, out = sim_run(scene, 200)
    assert sim.substeps == math.ceil(1.2 / SUBSTEP_FRACTION)
    assert sim.substeps_taken == 200 * sim.substeps
    assert energies(scene, out).max() <= energies(scene, out)[0] + 1e-9
    assert [e.kind for e in sim.events] == ["substepping"]
    assert "2.785" in sim.events[0].message and f"{sim.substeps} sub-steps" in sim.events[0].message


def test_with_the_stability_plan_off_each_step_is_whole_and_a_run_past_the_limit_diverges():
    """stability_plan off (a stability study): the step just past the limit is raw RK4's,
    bit for bit, until the divergence check holds the last sound state; just below, the
    same as with the plan on."""
    h = 0.01
    above = DAMPED.replace(step_size=h, stability_plan="off",
                           damping=1.2 * RK4_REAL_LIMIT / (h * worst_stiffness(RODS)))
    sim, out = sim_run(above, 200)
    assert sim.substeps == 1 and sim.diverged
    assert "2.785" in sim.events[0].message and "stability_plan off" in sim.events[0].message
    sound = next(k for k, y in enumerate(out) if y == out[-1])
    assert 0 < sound and out[:sound + 1] == raw_rk4_run(above, sound)
    below = above.replace(damping=0.99 * RK4_REAL_LIMIT / (h * worst_stiffness(RODS)))
    assert sim_run(below, 100)[1] == sim_run(below.replace(stability_plan="on"), 100)[1]
    with pytest.raises(SceneError, match="stability_plan 'never' is unknown"):
        DAMPED.replace(stability_plan="never")


def radau_positions(scene, times):
    arm = scene.arm

    def f(_, s):
        a1, a2 = model.forward_dynamics(arm, s[:2], s[2:], gravity=scene.gravity, damping=scene.damping)
        return [s[2], s[3], a1, a2]

    y0 = [*scene.initial_positions, *scene.initial_velocities]
    return solve_ivp(f, (0.0, times[-1]), y0, method="Radau", rtol=1e-10, atol=1e-12,
                     t_eval=times).y.T[:, :2]


@pytest.mark.parametrize("damping,h", [(5.0, 0.05), (50.0, 0.01), (500.0, 0.05), (1e4, 0.05),
                                       (1e4, 1e-3)])
def test_stiff_damping_stays_close_to_radau_and_passive(damping, h):
    scene = MOVING.replace(damping=damping, step_size=h)
    steps = round(0.5 / h)
    sim, out = sim_run(scene, steps)
    assert sim.substeps > 1
    reference = radau_positions(scene, np.arange(steps + 1) * h)
    assert np.abs(np.array([y[:2] for y in out]) - reference).max() < 1e-3
    e = energies(scene, out)
    assert np.all(np.diff(e) <= 1e-9)                          # the true energy only falls
    assert abs(sim.residual()) < 1e-2 * abs(e[0] - e[-1])      # and the books still balance


# --- fast spins and long runs ------------------------------------------------------------------

def test_fast_spin_stays_unwrapped_and_exact():
    """Rigid spin with gravity off: q2 stays 0, so RK4 is exact and q1 = 100 t, unwrapped."""
    sim = Simulator(Scene(gravity=0.0, initial_velocities=(100.0, 0.0), step_size=1e-3))
    for _ in range(10_000):
        sim.step()
    assert sim.state[1] == 0.0 and sim.state[3] == 0.0
    assert sim.state[0] == pytest.approx(1000.0, rel=1e-12)    # 159 turns, not wrapped


@pytest.mark.parametrize("velocities", [(100.0, 0.0), (0.0, 100.0), (100.0, -100.0), (-70.0, 70.0)])
def test_fast_motion_under_gravity_stays_finite_with_small_drift(velocities):
    sim = Simulator(Scene(initial_positions=(0.0, 0.3), initial_velocities=velocities, step_size=1e-3))
    worst = 0.0
    for _ in range(5_000):
        sim.step()
        worst = max(worst, abs(sim.residual()))
    assert all(math.isfinite(v) for v in sim.state) and not sim.refused_steps
    assert worst < 1e-3 * sim.initial_energy


def test_long_run_one_minute_at_one_millisecond():
    sim = Simulator(load_scene("release").replace(step_size=1e-3))
    drift = sim.run(60.0)
    assert all(math.isfinite(v) for v in sim.state)
    assert sim.time == pytest.approx(60.0, abs=1e-12)
    assert drift < 1e-6


# --- extreme arms ------------------------------------------------------------------------------

EXTREME = list(itertools.product((1e-3, 1.0, 1e3), (0.01, 1.0, 10.0), (0.01, 1.0, 10.0)))


def rod_scene(mass_ratio, l1, l2, **kw):
    return Scene(link_lengths=(l1, l2), link_masses=(1.0, mass_ratio), com_distances=(l1 / 2, l2 / 2),
                 com_inertias=(l1 * l1 / 12, mass_ratio * l2 * l2 / 12), **kw)


@pytest.mark.parametrize("mass_ratio,l1,l2", EXTREME)
def test_extreme_arm_solve_residual_is_at_rounding_level(mass_ratio, l1, l2):
    arm = rod_scene(mass_ratio, l1, l2).arm
    rng = np.random.default_rng(6)
    for _ in range(50):
        q, qd, tau = rng.uniform(-4, 4, 2), rng.uniform(-10, 10, 2), rng.uniform(-5, 5, 2)
        qdd = model.forward_dynamics(arm, q, qd, tau, 9.81, 0.3)
        back = model.inverse_dynamics(arm, q, qd, qdd, 9.81, 0.3)
        m11, m12, m22 = model.mass_matrix(arm, q)
        terms = [*model.velocity_torque(arm, q, qd), *model.gravity_torque(arm, q, 9.81), *tau]
        scale = (abs(m11) + 2 * abs(m12) + abs(m22)) * np.abs(qdd).sum() + np.abs(terms).sum() \
            + 0.3 * np.abs(qd).sum()
        assert np.abs(np.subtract(back, tau)).max() <= 4 * np.finfo(float).eps * scale


@pytest.mark.parametrize("mass_ratio,l1,l2", EXTREME)
def test_extreme_arm_simulates_accurately_at_its_own_time_scale(mass_ratio, l1, l2):
    arm = rod_scene(mass_ratio, l1, l2).arm
    # the fastest gravity swing: omega^2 <= gravity (k1 + k2) lambda_max(M^-1)
    omega = math.sqrt(9.81 * sum(arm.gravity_coefficients) * worst_stiffness(arm))
    sim = Simulator(rod_scene(mass_ratio, l1, l2, initial_positions=(0.3, 1.0), step_size=0.02 / omega))
    worst = 0.0
    for _ in range(2000):
        sim.step()
        worst = max(worst, abs(sim.residual()))
    assert worst < 1e-6 * 9.81 * sum(arm.gravity_coefficients)


# --- never non-finite --------------------------------------------------------------------------

def test_a_step_that_overflows_is_refused_and_the_state_held():
    sim = Simulator(DAMPED.replace(policy="constant", constant_torque=(1e308, 0.0)))
    start = sim.state
    for _ in range(5):
        sim.step()
    assert sim.state == start and sim.holding and sim.refused_steps == 5
    assert sim.steps == 5                      # time goes on; the arm is held
    assert "holding the last finite state" in sim.fault
    assert [e.kind for e in sim.events] == ["fault"]           # one event per run of refusals


def test_a_nan_command_is_refused_then_the_arm_recovers():
    heard = []
    sim = Simulator(DAMPED.replace(policy="command"))
    sim.event_listeners.append(heard.append)
    sim.set_command(1.0, 0.0)
    sim.step()
    good = sim.state
    sim.set_command(float("nan"), 0.0)
    sim.step()
    assert sim.state == good and sim.holding
    assert "qd1 = nan" in sim.fault and "work = nan" in sim.fault
    sim.set_command(float("inf"), 0.0)
    sim.step()
    assert sim.state == good and sim.refused_steps == 2
    sim.set_command(0.5, 0.0)
    sim.step()
    assert sim.state != good and not sim.holding and all(math.isfinite(v) for v in sim.state)
    assert [e.kind for e in heard] == ["fault"] and heard[0].t == pytest.approx(0.01)
    sim.reset()
    assert sim.fault is None and sim.refused_steps == 0 and not sim.holding


def test_a_large_but_finite_sum_is_not_mistaken_for_overflow():
    # positions near 1e308 add up to inf; each is finite, so the step is taken, not refused
    # as non-finite; the divergence check, which sees every state, then finds its angles
    # past MAX_ANGLE (no motion at all) and holds the last sound state
    sim = Simulator(Scene(gravity=0.0, step_size=0.01))
    sim.state = (1.5e308, 1.5e308, 0.0, 0.0)
    sim.step()
    assert "would make" not in sim.fault and sim.diverged.startswith(
        "diverged: an angle passed 1e+06 rad")


# --- the issue's d x step range on the damped scene --------------------------------------------

@pytest.mark.parametrize("h", [1e-4, 1e-3, 0.01, 0.05])
@pytest.mark.parametrize("damping", [0.0, 0.01, 0.5, 5.0, 18.5, 50.0, 500.0, 5000.0, 1e4])
def test_damped_release_is_passive_over_the_whole_range(damping, h):
    """E(t) <= E(0) + 1e-6 J + the d = 0 run's rise at the same step, for 0.2 s or 2000 steps."""
    steps = min(2000, round(0.2 / h))
    scene = DAMPED.replace(damping=damping, step_size=h, initial_velocities=(2.0, -3.0))
    sim, out = sim_run(scene, steps)
    assert all(math.isfinite(v) for y in out for v in y) and not sim.refused_steps
    free = energies(scene, raw_rk4_run(scene.replace(damping=0.0), steps))
    drift = np.maximum.accumulate(np.maximum(free - free[0], 0.0))
    e = energies(scene, out)
    assert (e - e[0] - drift).max() <= 1e-6


def test_arm_sim_run_says_when_it_sub_stepped_or_held_and_a_fault_exits_1(capsys):
    from arm_sim_ros.tools.cli import main

    assert main(["run", "--scene", "damped_release", "--set", "damping=1e4", "--duration", "0.1"]) == 0
    assert "arm-sim: substepping at t = 0 s" in capsys.readouterr().err
    assert main(["run", "--set", "initial_velocities=5e153,5e153", "--duration", "0.02"]) == 1
    err = capsys.readouterr().err
    assert "arm-sim: fault" in err and "holding the last finite state" in err
