"""Every figure the explainer prints, to the digits it prints it."""
from math import pi

import pytest

from arm_sim_ros.physics import model
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator

RODS = model.ArmParameters()
GRAVITY = 9.81


def printed(values, digits=6):
    """Format as the explainer does (`f"{x:.6f}"`), so a test fails on the last printed digit."""
    if isinstance(values, float):
        return f"{values:.{digits}f}"
    return "(" + ", ".join(f"{x:.{digits}f}" for x in values) + ")"


def run(scene_name, duration=None, **overrides):
    """The explainer's program: plain RK4 at h, no tolerance splitting its steps (the
    default tolerance does split release's steps where the elbow whips; --tolerance 0
    reproduces these figures from the command line)."""
    scene = load_scene(scene_name).replace(**({"tolerance": 0.0} | overrides))
    sim = Simulator(scene)
    drift = sim.run(scene.duration if duration is None else duration)
    return sim, drift


# Calculate the first gravity-driven acceleration

def test_first_gravity_accelerations():
    qdd = model.forward_dynamics(RODS, (0.0, 0.0), (0.0, 0.0), gravity=GRAVITY)
    assert printed(qdd) == "(-12.612857, 16.817143)"
    assert printed(qdd[0] + qdd[1]) == "4.204286"  # link 2's absolute angular acceleration


def test_first_gravity_terms():
    assert model.gravity_torque(RODS, (0.0, 0.0), GRAVITY) == pytest.approx((19.62, 4.905), abs=1e-12)
    assert model.velocity_torque(RODS, (0.0, 0.0), (0.0, 0.0)) == (0.0, 0.0)


def test_tip_accelerates_downward_at_release():
    qdd = model.forward_dynamics(RODS, (0.0, 0.0), (0.0, 0.0), gravity=GRAVITY)
    # At rest the tip's vertical acceleration is the Jacobian row times qdd: l1 cos q1 + l2 cos(q1+q2).
    l1, l2 = RODS.link_lengths
    assert printed(l1 * qdd[0] + l2 * (qdd[0] + qdd[1])) == "-8.408571"


# Let the mass matrix couple the joints

def mass_times(q, qdd):
    m11, m12, m22 = model.mass_matrix(RODS, q)
    return m11 * qdd[0] + m12 * qdd[1], m12 * qdd[0] + m22 * qdd[1]


def test_shoulder_torque_couples_into_the_elbow():
    qdd = model.forward_dynamics(RODS, (0.0, 0.0), (0.0, 0.0), torque=(1.0, 0.0))
    assert qdd == pytest.approx((12 / 7, -30 / 7), abs=1e-14)
    assert printed(qdd) == "(1.714286, -4.285714)"
    assert mass_times((0.0, 0.0), qdd) == pytest.approx((1.0, 0.0), abs=1e-14)


def test_exercise_1_doubled_shoulder_torque():
    qdd = model.forward_dynamics(RODS, (0.0, 0.0), (0.0, 0.0), torque=(2.0, 0.0))
    assert printed(qdd) == "(3.428571, -8.571429)"
    assert qdd == pytest.approx((24 / 7, -60 / 7), abs=1e-14)
    assert mass_times((0.0, 0.0), qdd) == pytest.approx((2.0, 0.0), abs=1e-14)


def test_mass_matrix_at_full_extension():
    m11, m12, m22 = model.mass_matrix(RODS, (0.0, 0.0))
    assert (m11, m12, m22) == pytest.approx((8 / 3, 5 / 6, 1 / 3), abs=1e-15)
    assert m11 * m22 - m12 * m12 == pytest.approx(7 / 36, abs=1e-15)


def test_shoulder_torque_scene_starts_with_the_coupling_accelerations():
    sim = Simulator(load_scene("shoulder_torque_no_gravity"))
    assert sim.dynamics.function(0.0, 0.0, 0.0, 0.0)[:2] == pytest.approx((12 / 7, -30 / 7), abs=1e-14)


# Recompute gravity compensation as the arm moves

def test_gravity_compensation_torque_on_moving_preset_at_half_second():
    sim, _ = run("moving_gravity_compensation", 0.5)
    assert printed(sim.sample().tau) == "(19.010062, 4.752515)"


def test_gravity_compensation_holds_at_rest():
    sim, drift = run("gravity_compensation_at_rest", 2.0)
    assert sim.state[:4] == (0.0, 0.0, 0.0, 0.0)
    assert drift == 0.0


# Expected output of the explainer's program, line by line

def test_release_h_0_01():
    sim, _ = run("release", 0.5, step_size=0.01)
    s = sim.sample()
    assert printed(s.q) == "(-1.122654, 0.593820)"
    assert printed(s.qd) == "(-2.414309, -3.534794)"
    assert printed(s.total - sim.initial_energy) == "0.000002"


def test_release_2s_max_drift_h_0_01():
    _, drift = run("release", 2.0, step_size=0.01)
    assert printed(drift, 9) == "0.000145388"


def test_release_h_0_005():
    sim, _ = run("release", 0.5, step_size=0.005)
    s = sim.sample()
    assert printed(s.q) == "(-1.122654, 0.593820)"
    assert printed(s.qd) == "(-2.414308, -3.534796)"
    assert printed(s.total - sim.initial_energy) == "0.000000"


def test_release_2s_max_drift_h_0_005():
    _, drift = run("release", 2.0, step_size=0.005)
    assert printed(drift, 9) == "0.000011084"


def test_shoulder_torque_work_equals_shoulder_angle():
    sim, _ = run("shoulder_torque_no_gravity", 0.5)
    s = sim.sample()
    assert printed(s.q[0]) == "0.202009"
    assert printed(s.total - sim.initial_energy) == "0.202009"
    assert printed(s.work) == "0.202009"   # W = q1(t) - q1(0) for 1 N m at the shoulder


def test_moving_gravity_compensation_state():
    sim, _ = run("moving_gravity_compensation", 0.5)
    s = sim.sample()
    assert printed(s.q) == "(0.250000, 0.000000)"
    assert printed(s.qd) == "(0.500000, 0.000000)"


def test_moving_frozen_gravity_state():
    sim, _ = run("moving_frozen_gravity", 0.5)
    s = sim.sample()
    assert printed(s.q) == "(0.258510, -0.011739)"
    assert printed(s.qd) == "(0.570046, -0.099129)"


# Try it yourself

def test_exercise_2_motion_and_energy_at_1s():
    sim, _ = run("moving_gravity_compensation", 1.0)
    s = sim.sample()
    assert printed(s.q) == "(0.500000, 0.000000)"
    assert printed(s.qd) == "(0.500000, 0.000000)"
    assert s.kinetic == pytest.approx(1 / 3, abs=1e-12)
    assert printed(s.potential) == "9.406329"
    assert printed(s.work) == "9.406329"     # the actuators supply the potential energy gained


def test_smaller_step_reduces_two_second_drift():
    _, coarse = run("release", 2.0, step_size=0.01)
    _, fine = run("release", 2.0, step_size=0.005)
    _, finest = run("release", 2.0, step_size=0.0005)
    assert finest < fine < coarse


# Replay presets and energy accounting

def test_downward_equilibrium_energy_and_rest():
    sim, drift = run("downward_equilibrium", 2.0)
    assert sim.initial_energy == pytest.approx(-19.62, abs=1e-12)
    assert sim.state[0] == pytest.approx(-pi / 2, abs=1e-12)
    assert max(abs(v) for v in sim.state[1:4]) < 1e-12
    assert drift < 1e-12


def test_damped_release_loses_energy_to_damping():
    sim = Simulator(load_scene("damped_release"))
    totals, dissipated = [], []
    sim.run(2.0, lambda s: (totals.append(s.sample().total), dissipated.append(s.sample().dissipated)))
    assert totals[-1] < totals[0] - 1.0
    assert all(b >= a for a, b in zip(dissipated, dissipated[1:]))
    assert abs(sim.residual()) < 1e-5


def test_energy_balance_with_damping_and_torque_together():
    scene = load_scene("release").replace(damping=0.7, policy="constant", constant_torque=(3.0, -1.0))
    sim = Simulator(scene)
    largest = sim.run(2.0)
    s = sim.sample()
    assert s.work != 0.0 and s.dissipated > 0.0
    # The residual is RK4 truncation error: a small fraction of the energies exchanged.
    assert largest < 1e-4 * (abs(s.work) + s.dissipated + abs(s.kinetic))
    fine = Simulator(scene.replace(step_size=0.001))
    assert fine.run(2.0) < largest / 1000
