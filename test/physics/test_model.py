"""The general planar 2R model against an independent derivation from link kinematics."""
import random
from math import cos, sin

import numpy as np
import pytest

from arm_sim_ros.physics import model
from arm_sim_ros.physics.model import ArmParameters, ParameterError

ARMS = [
    ArmParameters(),
    ArmParameters(link_lengths=(0.7, 1.3), link_masses=(2.0, 0.5), com_distances=(0.3, 0.9),
                  com_inertias=(0.05, 0.2)),
    ArmParameters(link_lengths=(2.0, 0.4), link_masses=(0.3, 5.0), com_distances=(1.1, -0.1),
                  com_inertias=(0.0, 0.01)),
]


def com_positions(arm, q):
    (l1, _), (r1, r2) = arm.link_lengths, arm.com_distances
    p1 = np.array([r1 * cos(q[0]), r1 * sin(q[0])])
    p2 = np.array([l1 * cos(q[0]) + r2 * cos(q[0] + q[1]), l1 * sin(q[0]) + r2 * sin(q[0] + q[1])])
    return p1, p2


def jacobians(arm, q):
    """COM velocity Jacobians d p_i / d q, differentiated by hand from com_positions."""
    (l1, _), (r1, r2) = arm.link_lengths, arm.com_distances
    s1, c1, s12, c12 = sin(q[0]), cos(q[0]), sin(q[0] + q[1]), cos(q[0] + q[1])
    j1 = np.array([[-r1 * s1, 0.0], [r1 * c1, 0.0]])
    j2 = np.array([[-l1 * s1 - r2 * s12, -r2 * s12], [l1 * c1 + r2 * c12, r2 * c12]])
    return j1, j2


def independent_mass_matrix(arm, q):
    """M = sum m Jv^T Jv + I Jw^T Jw, with link angular-velocity Jacobians [1, 0] and [1, 1]."""
    j1, j2 = jacobians(arm, np.asarray(q, float))
    (m1, m2), (i1, i2) = arm.link_masses, arm.com_inertias
    w1, w2 = np.array([[1.0, 0.0]]), np.array([[1.0, 1.0]])
    return m1 * j1.T @ j1 + m2 * j2.T @ j2 + i1 * w1.T @ w1 + i2 * w2.T @ w2


def states(n, seed=1):
    rng = random.Random(seed)
    return [((rng.uniform(-4, 4), rng.uniform(-4, 4)), (rng.uniform(-5, 5), rng.uniform(-5, 5)))
            for _ in range(n)]


@pytest.mark.parametrize("arm", ARMS)
def test_mass_matrix_matches_kinematic_derivation(arm):
    for q, _ in states(20):
        m11, m12, m22 = model.mass_matrix(arm, q)
        assert np.array([[m11, m12], [m12, m22]]) == pytest.approx(independent_mass_matrix(arm, q), abs=1e-8)


@pytest.mark.parametrize("arm", ARMS)
def test_velocity_torque_is_christoffel_of_mass_matrix(arm):
    # c_i = sum_jk (dM_ij/dq_k - 1/2 dM_jk/dq_i) qd_j qd_k, derivatives by central differences.
    eps = 1e-5
    for q, qd in states(10):
        q = np.asarray(q)
        dm = []
        for k in range(2):
            dq = np.zeros(2)
            dq[k] = eps
            dm.append((independent_mass_matrix(arm, q + dq) - independent_mass_matrix(arm, q - dq)) / (2 * eps))
        c = [sum((dm[k][i, j] - 0.5 * dm[i][j, k]) * qd[j] * qd[k] for j in range(2) for k in range(2))
             for i in range(2)]
        assert model.velocity_torque(arm, q, qd) == pytest.approx(c, abs=1e-7)


@pytest.mark.parametrize("arm", ARMS)
def test_gravity_torque_is_gradient_of_potential(arm):
    eps = 1e-6
    for q, _ in states(10):
        grad = []
        for k in range(2):
            dq = [0.0, 0.0]
            dq[k] = eps
            plus = model.potential_energy(arm, (q[0] + dq[0], q[1] + dq[1]), 9.81)
            minus = model.potential_energy(arm, (q[0] - dq[0], q[1] - dq[1]), 9.81)
            grad.append((plus - minus) / (2 * eps))
        assert model.gravity_torque(arm, q, 9.81) == pytest.approx(grad, abs=1e-6)


@pytest.mark.parametrize("arm", ARMS)
def test_potential_is_mass_times_com_height(arm):
    for q, _ in states(10):
        heights = [p[1] for p in com_positions(arm, q)]
        expected = 9.81 * sum(m * y for m, y in zip(arm.link_masses, heights))
        assert model.potential_energy(arm, q, 9.81) == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize("arm", ARMS)
def test_inverse_dynamics_undoes_forward_dynamics(arm):
    rng = random.Random(3)
    for q, qd in states(20):
        tau = (rng.uniform(-10, 10), rng.uniform(-10, 10))
        qdd = model.forward_dynamics(arm, q, qd, tau, gravity=9.81, damping=0.3)
        assert model.inverse_dynamics(arm, q, qd, qdd, gravity=9.81, damping=0.3) == pytest.approx(tau, abs=1e-10)


def test_kinetic_energy_is_half_qd_m_qd():
    arm = ARMS[1]
    for q, qd in states(10):
        m = independent_mass_matrix(arm, q)
        assert model.kinetic_energy(arm, q, qd) == pytest.approx(0.5 * np.asarray(qd) @ m @ np.asarray(qd), rel=1e-7)


def test_link_points_follow_the_explainer_axes():
    base, elbow, tip = model.link_points(ArmParameters(), (np.pi / 2, -np.pi / 2))
    assert base == (0.0, 0.0)
    assert elbow == pytest.approx((0.0, 1.0), abs=1e-15)   # q1 counter-clockwise from +x, y up
    assert tip == pytest.approx((1.0, 1.0), abs=1e-15)     # q2 relative to link 1


@pytest.mark.parametrize("kwargs, message", [
    ({"link_masses": (0.0, 1.0)}, "link_masses[0] = 0.0 is impossible"),
    ({"link_lengths": (1.0, -1.0)}, "link_lengths[1] = -1.0 is impossible"),
    ({"com_inertias": (-0.1, 0.1)}, "com_inertias[0] = -0.1 is impossible"),
    ({"link_masses": (1.0, float("nan"))}, "must be finite"),
    ({"link_masses": (1.0,)}, "needs two values"),
    ({"com_distances": (0.5, 0.0), "com_inertias": (0.1, 0.0)}, "singular"),
])
def test_impossible_arms_are_refused(kwargs, message):
    with pytest.raises(ParameterError, match=message.replace("[", r"\[").replace("]", r"\]")):
        ArmParameters(**kwargs)


@pytest.mark.parametrize("lengths, payload", [((1e-12, 1e200), 7.0), ((1.0, 1e160), 1e200),
                                               ((1.0, 1e200), 1e308)])
def test_a_payload_folded_beyond_the_doubles_is_refused_in_the_physics_words(lengths, payload):
    # (length - com)^2 raises OverflowError past the doubles; a product gives inf instead
    arm = ArmParameters(link_lengths=lengths, com_distances=(0.5, 0.5))
    with pytest.raises(ParameterError, match="payload of .* kg at the tip of link 2 .* beyond "
                                             "double precision"):
        arm.with_payload(payload)


def test_point_mass_links_are_allowed():
    arm = ArmParameters(com_distances=(1.0, 1.0), com_inertias=(0.0, 0.0))
    m11, m12, m22 = model.mass_matrix(arm, (0.0, 0.0))
    assert m11 * m22 - m12 * m12 > 0
