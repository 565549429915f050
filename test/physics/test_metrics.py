"""The figures a controller's author asserts on and a sweep tabulates (physics/metrics.py),
each against a response whose figure is known in closed form."""
from math import exp, log, pi, sqrt

import numpy as np
import pytest

from arm_sim_ros.physics.metrics import NAMES, Performance, performance

DT = 1e-3


def first_order(tau_c=0.1, target=(0.5, -0.3), seconds=2.0):
    """q(t) = target (1 - exp(-t / tau_c)): never overshoots."""
    t = np.arange(0.0, seconds + DT / 2, DT)
    q = np.outer(1.0 - np.exp(-t / tau_c), target)
    return t, q, np.zeros_like(q), np.array(target)


def second_order(zeta=0.2, omega=10.0, step=1.0, seconds=5.0):
    """The unit step response of an underdamped second-order system, both joints."""
    t = np.arange(0.0, seconds + DT / 2, DT)
    wd = omega * sqrt(1 - zeta ** 2)
    x = 1 - np.exp(-zeta * omega * t) * (np.cos(wd * t) + zeta / sqrt(1 - zeta ** 2)
                                         * np.sin(wd * t))
    q = step * np.stack([x, x], axis=-1)
    return t, q, np.zeros_like(q), np.array([step, step])


def test_settle_time_of_a_first_order_approach_is_tau_ln_50():
    t, q, tau, target = first_order()
    settle = performance(t, q, tau, target)["settle_time"]
    exact = 0.1 * log(1 / 0.02)                  # exp(-t/tau) = 2 %
    assert np.all(settle >= exact) and np.all(settle < exact + DT + 1e-12)


def test_a_first_order_approach_never_overshoots():
    t, q, tau, target = first_order()
    assert np.all(performance(t, q, tau, target)["overshoot"] == 0.0)


def test_overshoot_of_an_underdamped_step_is_exp_of_minus_zeta_pi_over_root():
    zeta = 0.2
    t, q, tau, target = second_order(zeta)
    exact = exp(-zeta * pi / sqrt(1 - zeta ** 2))          # 52.7 % of the step
    assert performance(t, q, tau, target)["overshoot"] == pytest.approx([exact, exact],
                                                                         rel=1e-5)


def test_a_move_in_the_negative_direction_measures_its_overshoot_below_the_target():
    t, q, tau, target = second_order(step=-2.0)
    exact = 2.0 * exp(-0.2 * pi / sqrt(1 - 0.04))
    assert performance(t, q, tau, target)["overshoot"] == pytest.approx([exact] * 2, rel=1e-5)


def test_a_hold_counts_overshoot_both_ways_and_needs_a_band():
    t = np.arange(0.0, 1.0 + DT / 2, DT)
    q = np.stack([0.01 * np.sin(2 * pi * t), -0.03 * np.sin(2 * pi * t)], axis=-1)
    with pytest.raises(ValueError, match="needs a band"):
        performance(t, q, np.zeros_like(q), [0.0, 0.0])
    figures = performance(t, q, np.zeros_like(q), [0.0, 0.0], band=0.02)
    assert figures["overshoot"] == pytest.approx([0.01, 0.03], rel=1e-6)
    # joint 1 never left its band: settled from the first sample; joint 2 never settles
    # before its last swing out, and ends inside (sin(2 pi) = 0)
    assert figures["settle_time"][0] == 0.0
    assert 0.5 < figures["settle_time"][1] < 1.0


def test_a_trace_that_ends_outside_its_band_has_not_settled():
    t, q, tau, target = first_order(tau_c=10.0, seconds=1.0)
    assert np.all(np.isnan(performance(t, q, tau, target)["settle_time"]))


def test_tracking_error_of_a_sine_error_is_its_amplitude_over_root_two():
    t = np.arange(0.0, 4.0, DT)                    # whole periods
    reference = np.stack([np.sin(t), np.cos(t)], axis=-1)
    q = reference + np.stack([0.1 * np.sin(2 * pi * t), 0.2 * np.sin(2 * pi * t)], axis=-1)
    figures = Performance(None, float(t[-1]), band=1.0)
    figures.update(t, q, np.zeros_like(q), q_ref=reference)
    assert figures.figures()["tracking_error"] == pytest.approx([0.1 / sqrt(2), 0.2 / sqrt(2)],
                                                                rel=1e-6)


def test_tracking_error_counts_from_after():
    t = np.arange(0.0, 2.0 + DT / 2, DT)
    q = np.where(t[:, None] < 1.0, 1.0, 0.25) * np.ones((len(t), 2))
    figures = performance(t, q, np.zeros_like(q), [0.0, 0.0], band=0.1, after=1.0)
    assert figures["tracking_error"] == pytest.approx([0.25, 0.25])


def test_steady_state_error_is_the_mean_error_of_the_last_tenth():
    t = np.arange(0.0, 10.0 + DT / 2, DT)
    q = np.where(t[:, None] >= 9.0, 0.5 + 0.01 * (t[:, None] - 9.0), 0.0) * np.ones((1, 2))
    figures = performance(t, q, np.zeros_like(q), [0.5, 0.5])
    assert figures["steady_state_error"] == pytest.approx([0.005, 0.005], rel=1e-3)


def test_peak_torque_is_the_largest_magnitude_per_joint():
    t, q, _, target = first_order()
    tau = np.stack([np.sin(7 * t) * 3.0, -np.abs(np.cos(t)) * 4.0], axis=-1)
    assert performance(t, q, tau, target)["peak_torque"] == pytest.approx(
        [np.abs(tau[:, 0]).max(), 4.0])


def test_chunks_in_any_sizes_give_the_whole_trace_figures():
    """Bit for bit where a figure is a max or an index; sums to their rounding."""
    t, q, _, target = second_order()
    tau = np.sin(3 * t)[:, None] * np.ones((1, 2))
    whole = performance(t, q, tau, target, after=0.5)
    for cuts in ([1], [7, 300, 301, 4000], list(range(13, len(t), 997))):
        pieces = Performance(target, float(t[-1]), after=0.5)
        for part in np.split(np.arange(len(t)), cuts):
            pieces.update(t[part], q[part], tau[part])
        for name in ("peak_torque", "overshoot", "settle_time"):
            np.testing.assert_array_equal(pieces.figures()[name], whole[name], err_msg=name)
        for name in ("tracking_error", "steady_state_error"):
            np.testing.assert_allclose(pieces.figures()[name], whole[name], rtol=1e-13)


def test_many_samples_at_once_give_each_sample_its_own_figures():
    traces = [second_order(zeta) for zeta in (0.1, 0.3, 0.7)]
    t = traces[0][0]
    q = np.stack([trace[1] for trace in traces])           # (3, K, 2)
    tau = np.stack([np.sin(z * 9 * t)[:, None] * np.ones((1, 2)) for z in (1, 2, 3)])
    together = performance(t, q, tau, [1.0, 1.0])
    for i in range(3):
        alone = performance(t, q[i], tau[i], [1.0, 1.0])
        for name in NAMES:
            np.testing.assert_array_equal(together[name][i], alone[name], err_msg=name)
