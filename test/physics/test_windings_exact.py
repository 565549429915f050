"""The exponential RK4 (integrator `exponential_rk4`): winding currents' decay -R/L and
their torque on the joints exact within the step (stepping/exponential.py).

Checked against test_effects' independent FirstPrinciples (DOP853 at 1e-12, or Radau where
the windings are stiff, on the equations written from scratch): fourth order in the
mechanics on the geared arm, no sub-steps at h = 1 ms where rk4 needs 3, stiff windings as
accurate as rk4 on windings it need not sub-step, and RK4 itself, bit for bit, without
windings.
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from arm_sim_ros.physics.stepping.exponential import compile_exponential_step, exponential_rk4, phi
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.physics.stepping.stability import exponential_radius

from physics.test_effects import FirstPrinciples

GEARED = load_scene("geared_arm").replace(friction=None, joint_limits=None, tolerance=0.0)


def test_phi_functions_agree_across_the_series_switch_and_give_rk4_at_zero():
    coefficients = exponential_rk4(0.0)
    assert coefficients[:11] == pytest.approx((1, 1, 0.5, 0, 0.5, 0, 1, 1 / 6, 1 / 3, 1 / 3,
                                               1 / 6), abs=1e-15)
    # the coupling's divided differences at 0: the current's integral over each stage
    assert coefficients[11:] == pytest.approx((0.5, 1, 1 / 8, 1 / 24, 1 / 12, 1 / 6, 1 / 3,
                                               1 / 6, 1 / 6, 1 / 6, 0), abs=1e-15)
    for z in (-0.9999999, -1.0000001, -3.0):
        e, p1, p2, p3, p4 = phi(z)
        assert e == pytest.approx(math.exp(z), rel=1e-15)
        assert p1 == pytest.approx(math.expm1(z) / z, rel=1e-14)
        assert p2 == pytest.approx((p1 - 1.0) / z, rel=1e-12)
        assert p3 == pytest.approx((p2 - 0.5) / z, rel=1e-11)
        assert p4 == pytest.approx((p3 - 1 / 6) / z, rel=1e-10)


def winding(lam, drive, pull=0.0):
    """f of a lone winding x' = drive - lam x whose current pulls joint 1 by `pull` x."""
    def f(q1, q2, u1, u2, x):
        return pull * x, 0.0, drive - lam * x
    f.response = lambda q1, q2: (pull, 0.0)
    return f


def test_a_winding_with_constant_drive_is_integrated_exactly_at_any_step():
    lam, drive = 1900.0, 5000.0
    step = compile_exponential_step(0, (lam,))
    for h in (1e-5, 1e-3, 0.1):
        y = step(winding(lam, drive), (0.0, 0.0, 0.0, 0.0, 0.0), h)
        assert y[4] == pytest.approx(drive / lam * -math.expm1(-lam * h), rel=1e-14)


def test_the_torque_of_a_current_switched_on_is_integrated_exactly_at_any_step():
    """A current rising as 1 - e^(-lam t) pulls the joint: the velocity takes its exact
    integral, however short L/R is against h. The step with the pole alone took RK4's
    quadrature of it, which counts the current at its start for 1/6 of the step: the
    velocity 0.84x at lam h = 100, the impulse the joint lacks while the current rises 17x
    the true one (an arm that sags 17x too far when its drivers switch on)."""
    lam, drive, pull = 1e5, 3e5, 2.0
    step = compile_exponential_step(0, (lam,))
    for h in (1e-5, 1e-3, 0.1):
        y = step(winding(lam, drive, pull), (0.0, 0.0, 0.0, 0.0, 0.0), h)
        exact = pull * drive / lam * (h + math.expm1(-lam * h) / lam)
        assert y[2] == pytest.approx(exact, rel=1e-12), h


def test_without_windings_it_is_rk4_bit_for_bit():
    scene = load_scene("release")
    a, b = Simulator(scene), Simulator(scene.replace(integrator="exponential_rk4"))
    a.run(0.5)
    b.run(0.5)
    assert a.state == b.state


def test_geared_arm_at_1ms_is_exponential_rk4_with_no_planned_sub_steps_where_rk4_takes_three():
    scene = load_scene("geared_arm")
    assert scene.integrator == "exponential_rk4"
    assert Simulator(scene).substeps == 1
    assert Simulator(scene.replace(integrator="rk4")).substeps == 3


def test_the_step_is_stable_where_the_plan_says_and_the_winding_stays_passive():
    # test problem i' = -x i - w u, u' = w i: |amplification| <= 1 at the planned step
    sim = Simulator(load_scene("geared_arm"))
    motors = next(e for e in sim.dynamics.active if e.name == "motors")
    for lam, p in motors.coupling(sim.arm):
        x = sim.step_size / sim.substeps * lam
        assert exponential_radius(x, x * x * p / (lam * lam), 0.0) <= 1.0
    assert exponential_radius(1e4, 1.0, 0.0) <= 1.0       # L/R << h: exact decay, no growth


def test_fourth_order_in_the_mechanics_against_the_first_principles_reference():
    T = 0.2
    y = FirstPrinciples(GEARED).solve(T)
    errors = []
    for h in (1e-3, 5e-4, 2.5e-4):
        sim = Simulator(GEARED.replace(step_size=h))
        assert sim.substeps == 1
        sim.run(T)
        errors.append(float(np.max(np.abs(np.array(sim.state[:4]) - y[:4]))))
    orders = [math.log2(a / b) for a, b in zip(errors, errors[1:])]
    assert min(orders) > 3.5, (errors, orders)
    assert errors[0] < 1e-5



def test_geared_arm_as_shipped_meets_its_tolerance_and_its_books_close():
    # friction, limits and clamps located as events, default tolerance, commanded from rest;
    # the truth: rk4 (3 sub-steps) at a tolerance 5e5 times tighter
    scene, seconds = load_scene("geared_arm"), 0.5
    runs = []
    for method, tolerance in (("exponential_rk4", scene.tolerance), ("rk4", 1e-10)):
        sim = Simulator(scene.replace(integrator=method, tolerance=tolerance))
        sim.set_command(10.0, -4.0)
        runs.append((sim, sim.run(seconds)))
    (sim, largest), (truth, _) = runs
    error = max(abs(a - b) for a, b in zip(sim.state[:4], truth.state[:4]))
    assert error <= scene.tolerance * seconds
    assert sim.substeps == 1 and sim.substeps_taken < sim.steps     # the tolerance splits few
    moved = max(abs(v) for v in sim.channel_values(sim.state).values())
    assert largest <= 1e-6 * moved, (largest, moved)


def errors_against_radau(scene, command, seconds):
    """(largest |q error|, largest |q, qd error|) at every step of a run against the
    first-principles equations on scipy's Radau (stiff windings) at rtol 1e-12."""
    reference = FirstPrinciples(scene, command=command)
    times = np.arange(scene.steps_for(seconds) + 1) * scene.step_size
    truth = solve_ivp(lambda t, y: reference.rhs(y, {}), (0.0, times[-1]), reference.y0,
                      method="Radau", t_eval=times, rtol=1e-12, atol=1e-13).y.T
    sim = Simulator(scene)
    sim.set_command(*command)
    states = [sim.state]
    for _ in times[1:]:
        sim.step()
        states.append(sim.state)
    error = np.abs(np.array(states)[:, :4] - truth[:, :4])
    return float(error[:, :2].max()), float(error.max())


def with_time_constant(seconds, integrator=""):
    """GEARED, moving and commanded, its windings' L/R = `seconds` (no clamps: the
    reference has no events)."""
    motors = {k: v for k, v in GEARED.motors.items() if k != "voltage_limit"}
    motors["inductance"] = [seconds * r for r in motors["resistance"]]
    return GEARED.replace(motors=motors, effort_limits=None, integrator=integrator,
                          initial_velocities=(0.5, -1.0))


@pytest.mark.parametrize("time_constant", [1e-5, 1e-4])
def test_stiff_windings_are_as_accurate_as_rk4_on_windings_it_need_not_sub_step(time_constant):
    """Issue 47: h = 1 ms, tolerance 0, the driver switching on under gravity compensation
    plus a command. With the winding's pole alone exact, the torque of the current rising
    within the step reached the motion by RK4's quadrature: 2.4e-4 rad at L/R = 10 µs and
    1.1e-4 at 100 µs (no method named: exponential_rk4), where rk4 is 1.4e-7 rad from the
    truth on windings of L/R = 1 ms (no sub-steps there). With the torque exact too: 3e-8
    and 1.4e-7 rad."""
    command, seconds = (10.0, -4.0), 1.0
    stiff = with_time_constant(time_constant)
    assert stiff.method == "exponential_rk4" and Simulator(stiff).substeps == 1
    plain = with_time_constant(1e-3, "rk4")
    assert Simulator(plain).substeps == 1
    q, state = errors_against_radau(stiff, command, seconds)
    q_rk4, state_rk4 = errors_against_radau(plain, command, seconds)
    assert q <= 2.0 * q_rk4 and state <= state_rk4, (q, q_rk4, state, state_rk4)


def test_the_currents_pull_on_the_joints_as_each_mode_lets_them():
    """The step's coupling (f.response, dynamics.response_source) is the rhs's own
    acceleration per ampere, mode by mode: M⁻¹kN where both joints move, none on a joint
    friction holds, whose velocity then stays exactly 0 under the exponential step."""
    sim = Simulator(load_scene("geared_arm"))
    for _ in range(300):
        sim.step()
    assert sim.switching.mode[:2] == ("stuck", "stuck") and sim.state[2:4] == (0.0, 0.0)
    y = (0.3, -0.8, 0.5, -1.0, 2.0, -1.5)
    for mode, f in [(None, sim.dynamics.function)] + [
            (m, sim.switching.functions(m)[0]) for m in (
                ("free", "free", 0, 0, (0, 0, 0, 0)), ("stuck", "free", 0, 0, (0, 0, 0, 0)),
                ("free", "stuck", 0, 0, (0, 0, 0, 0)), ("stuck", "stuck", 0, 0, (0, 0, 0, 0)))]:
        pull = f.response(*y[:2])
        for k in (0, 1):        # the accelerations are affine in each current
            moved = list(y)
            moved[4 + k] += 1.0
            expected = [a - b for a, b in zip(f(*moved)[:2], f(*y)[:2])]
            assert list(pull[2 * k:2 * k + 2]) == pytest.approx(expected, rel=1e-9, abs=1e-12), mode
