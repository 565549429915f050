"""Integrators as data: tableau order conditions, observed convergence orders, the embedded
pair's tolerance and landing, and RK4 unchanged bit for bit."""
from dataclasses import replace
from fractions import Fraction as F
from functools import lru_cache
from math import isnan, log

import pytest

from arm_sim_ros.physics.stepping.integrators import (DOPRI5, EULER, INTEGRATORS, RK4,
                                                      SEMI_IMPLICIT_EULER, ButcherTableau,
                                                      compile_step)
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.tools.accuracy.command import reference

RELEASE = load_scene("release")
FIXED_STEP_DOPRI5 = replace(DOPRI5, name="dopri5_fixed", embedded_b=None, embedded_order=0)


@lru_cache(maxsize=None)
def release_reference(duration, interval):
    times = [k * interval for k in range(round(duration / interval) + 1)]
    return times, reference(RELEASE, times)


def run_steps(tableau, h, duration, scene=RELEASE, **tolerances):
    sim = Simulator(scene)
    step = compile_step(tableau, len(sim.channels), **tolerances)
    y = sim.state
    for _ in range(round(duration / h)):
        y = step(sim.dynamics.function, y, h)
    return y


def error_at(tableau, h, duration=0.5):
    times, ref = release_reference(duration, duration)
    y = run_steps(tableau, h, duration)
    return max(abs(a - b) for a, b in zip(y[:4], ref[-1][:4]))


def fitted_order(tableau, steps):
    points = [(log(h), log(error_at(tableau, h))) for h in steps]
    mx = sum(x for x, _ in points) / len(points)
    my = sum(y for _, y in points) / len(points)
    return sum((x - mx) * (y - my) for x, y in points) / sum((x - mx) ** 2 for x, _ in points)


# The tableaux themselves: exact order conditions on the Fractions.

def order_conditions(t):
    """Residuals of the rooted-tree conditions up to order 4 (b weights with c = A 1)."""
    b, c, s = t.b, t.c, t.stages
    a = [[t.a[i][j] if j < i else F(0) for j in range(s)] for i in range(s)]
    ac = [sum(a[i][j] * c[j] for j in range(s)) for i in range(s)]
    conditions = {
        1: [sum(b) - 1],
        2: [sum(bi * ci for bi, ci in zip(b, c)) - F(1, 2)],
        3: [sum(bi * ci ** 2 for bi, ci in zip(b, c)) - F(1, 3),
            sum(bi * x for bi, x in zip(b, ac)) - F(1, 6)],
        4: [sum(bi * ci ** 3 for bi, ci in zip(b, c)) - F(1, 4),
            sum(b[i] * c[i] * ac[i] for i in range(s)) - F(1, 8),
            sum(b[i] * a[i][j] * c[j] ** 2 for i in range(s) for j in range(s)) - F(1, 12),
            sum(b[i] * a[i][j] * ac[j] for i in range(s) for j in range(s)) - F(1, 24)],
    }
    return conditions


@pytest.mark.parametrize("name", [n for n, t in INTEGRATORS.items() if t.position_a is None])
def test_tableau_satisfies_the_order_conditions_of_its_order(name):
    t = INTEGRATORS[name]
    conditions = order_conditions(t)
    for order in range(1, min(t.order, 4) + 1):
        assert all(r == 0 for r in conditions[order]), (name, order)
    if t.order < 4:   # and not those of the next order: the order is not understated
        assert any(r != 0 for r in conditions[t.order + 1])


def test_embedded_weights_are_fourth_order_and_differ_from_the_fifth():
    conditions = order_conditions(replace(DOPRI5, b=DOPRI5.embedded_b, embedded_b=None))
    assert all(r == 0 for order in (1, 2, 3, 4) for r in conditions[order])
    assert DOPRI5.embedded_b != DOPRI5.b


def test_malformed_tableaux_are_refused():
    with pytest.raises(ValueError, match="sum to c"):
        ButcherTableau("bad", c=(F(0), F(1, 2)), a=((), (F(1),)), b=(F(0), F(1)), order=2)
    with pytest.raises(ValueError, match="weights must sum to 1"):
        ButcherTableau("bad", c=(F(0),), a=((),), b=(F(1, 2),), order=1)
    with pytest.raises(ValueError, match="explicit"):
        ButcherTableau("bad", c=(F(0),), a=((F(0),),), b=(F(1),), order=1)


# RK4 unchanged.

def hand_rk4(f, s, h):
    """The explainer's RK4 written out by hand, in the compiled code's operation order."""
    q1, q2, u1, u2 = s
    k1 = (u1, u2, *f(q1, q2, u1, u2))
    k2 = (u1 + h * k1[2] / 2.0, u2 + h * k1[3] / 2.0)
    k2 += f(q1 + h * k1[0] / 2.0, q2 + h * k1[1] / 2.0, *k2)
    k3 = (u1 + h * k2[2] / 2.0, u2 + h * k2[3] / 2.0)
    k3 += f(q1 + h * k2[0] / 2.0, q2 + h * k2[1] / 2.0, *k3)
    k4 = (u1 + h * k3[2], u2 + h * k3[3])
    k4 += f(q1 + h * k3[0], q2 + h * k3[1], *k4)
    return tuple(x + h * (a + 2.0 * b + 2.0 * c + d) / 6.0
                 for x, a, b, c, d in zip(s, k1, k2, k3, k4))


def test_rk4_is_bit_for_bit_the_hand_written_rk4():
    sim = Simulator(RELEASE)
    s = sim.state
    for _ in range(50):
        sim.step()
        s = hand_rk4(sim.dynamics.function, s, 0.01)
        assert sim.state == s


def test_rk4_source_keeps_its_shape():
    source = compile_step(RK4, 0).source
    assert source.count("= f(") == 4
    assert "q1 + h * (v1_0 + 2.0 * v1_1 + 2.0 * v1_2 + v1_3) / 6.0" in source


# Observed convergence order on the release against the DOP853 reference.

def test_rk4_fitted_order_on_the_release_at_half_a_second_is_four():
    assert fitted_order(RK4, (0.01, 0.005, 0.0025, 0.00125)) == pytest.approx(4.0, abs=0.1)


@pytest.mark.parametrize("name, steps, slack", [
    ("euler", (0.001, 0.0005, 0.00025), 0.1),
    ("semi_implicit_euler", (0.001, 0.0005, 0.00025), 0.1),
    ("midpoint", (0.005, 0.0025, 0.00125), 0.1),
    ("rk38", (0.01, 0.005, 0.0025), 0.1),
    # DOPRI5's fifth-order error constant is small by design, so its sixth-order term
    # still shows until the errors meet round-off (~1e-13): only the finest clean pair.
    ("dopri5_fixed", (0.005, 0.0025), 0.25),
])
def test_observed_order_matches_theory(name, steps, slack):
    tableau = FIXED_STEP_DOPRI5 if name == "dopri5_fixed" else INTEGRATORS[name]
    assert fitted_order(tableau, steps) == pytest.approx(tableau.order, abs=slack)


def test_semi_implicit_euler_takes_one_evaluation_and_uses_the_new_velocity():
    calls = []

    def f(q1, q2, u1, u2):
        calls.append((q1, q2, u1, u2))
        return 2.0, -1.0

    y = compile_step(SEMI_IMPLICIT_EULER)(f, (0.0, 0.0, 1.0, 1.0), 0.1)
    assert calls == [(0.0, 0.0, 1.0, 1.0)]
    assert y == pytest.approx((0.1 * 1.2, 0.1 * 0.9, 1.2, 0.9), abs=1e-15)
    assert compile_step(EULER)(f, (0.0, 0.0, 1.0, 1.0), 0.1) == pytest.approx((0.1, 0.1, 1.2, 0.9))


# The accounting channels ride on the same stages with the same weights.

@pytest.mark.parametrize("name", [n for n, t in INTEGRATORS.items() if t.position_a is None])
def test_work_channel_uses_the_position_weights(name):
    # Shoulder torque 1 N m, elbow 0: work rate = qd1, so W = q1(t) - q1(0) step for step.
    scene = load_scene("shoulder_torque_no_gravity").replace(integrator=name)
    sim = Simulator(scene)
    sim.run(0.5)
    work = sim.state[4 + sim.channels.index("work")]
    assert work == pytest.approx(sim.state[0] - scene.initial_positions[0], abs=1e-14)


# The embedded pair.

@pytest.mark.parametrize("tolerance", [1e-6, 1e-8, 1e-10])
def test_dopri5_meets_its_tolerance_on_each_publish_interval(tolerance):
    # Local error of one simulator step (several sub-steps) from the reference state,
    # scaled as the controller scales it.
    times, ref = release_reference(0.5, 0.01)
    sim = Simulator(RELEASE)
    step = compile_step(DOPRI5, 0, rtol=tolerance, atol=tolerance)
    for start, target in zip(ref, ref[1:]):
        y = step(sim.dynamics.function, start[:4], 0.01)
        scaled = max(abs(a - b) / (tolerance + tolerance * abs(b)) for a, b in zip(y, target))
        assert scaled <= 1.0


def test_dopri5_global_error_follows_the_tolerance():
    times, ref = release_reference(0.5, 0.5)
    errors = []
    for tolerance in (1e-7, 1e-9, 1e-11):
        y = run_steps(DOPRI5, 0.01, 0.5, rtol=tolerance, atol=tolerance)
        errors.append(max(abs(a - b) for a, b in zip(y, ref[-1][:4])))
        assert errors[-1] < 10 * tolerance * (1 + max(abs(v) for v in ref[-1][:4]))
    assert errors[0] > errors[1] > errors[2]


def test_dopri5_lands_exactly_on_the_step_boundary():
    # With a loose tolerance the first attempt (the whole interval) is accepted: the
    # result is then exactly one fixed DOPRI5 step of length h, no more, no less.
    sim = Simulator(RELEASE)
    y0, f = sim.state, sim.dynamics.function
    adaptive = compile_step(DOPRI5, 0, rtol=1e-2, atol=1e-2)(f, y0, 0.01)
    assert adaptive == compile_step(FIXED_STEP_DOPRI5)(f, y0, 0.01)
    # With a tight one it takes sub-steps, and still ends at t = h (checked against the reference).
    calls = []
    counted = lambda *y: calls.append(1) or f(*y)
    tight = compile_step(DOPRI5, 0, rtol=1e-12, atol=1e-12)(counted, y0, 0.01)
    assert len(calls) > 7
    _, ref = release_reference(0.01, 0.01)
    assert tight == pytest.approx(ref[-1][:4], abs=1e-12)


def test_dopri5_gives_up_on_a_non_finite_state_instead_of_looping():
    sim = Simulator(RELEASE)
    y = compile_step(DOPRI5)(sim.dynamics.function, (float("nan"), 0.0, 0.0, 0.0), 0.01)
    assert all(isnan(v) for v in y)


def test_dopri5_refuses_non_positive_tolerances():
    with pytest.raises(ValueError, match="rtol and atol must be positive"):
        compile_step(DOPRI5, rtol=0.0)


@pytest.mark.parametrize("name", list(INTEGRATORS))
def test_every_integrator_is_selectable_by_the_scene_key(name):
    sim = Simulator(RELEASE.replace(integrator=name, step_size=0.001))
    sim.run(0.5)
    _, ref = release_reference(0.5, 0.5)
    tolerance = {1: 0.05, 2: 1e-4}.get(INTEGRATORS[name].order, 1e-7)
    assert sim.state[:4] == pytest.approx(ref[-1][:4], abs=tolerance)
