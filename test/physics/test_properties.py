"""Property-based (hypothesis) checks over states, parameters, damping and steps.

Passivity, as the issue states it: for a damped arm with no actuator work, any d in [0, 1e4]
and any step in [1e-4, 0.05], the state stays finite and the total energy never climbs above
E(0) by more than 1e-6 J plus what the same step drifts with d = 0 (the true energy only
falls). Examples are derandomized so the suite is deterministic; each run is capped at a
few thousand RK4 sub-steps to stay fast.
"""
import math

import numpy as np
from hypothesis import given, settings, strategies as st

from arm_sim_ros.physics import model
from arm_sim_ros.physics.scene import Scene, SceneError
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.physics.stepping.stability import worst_stiffness

SETTINGS = settings(max_examples=30, deadline=None, derandomize=True)   # 60: 25 s of the suite
SUBSTEP_BUDGET = 6000          # RK4 sub-steps per example

angles = st.floats(-math.pi, math.pi)
speeds = st.floats(-10.0, 10.0)
steps = st.floats(-4.0, math.log10(0.05)).map(lambda e: 10.0 ** e)
dampings = st.one_of(st.just(0.0), st.just(1e4), st.floats(-2.0, 4.0).map(lambda e: 10.0 ** e))


def trajectory_energies(scene):
    sim = Simulator(scene)
    count = max(2, min(200, SUBSTEP_BUDGET // sim.substeps))
    energies = [sim.energy(sim.state)]
    for _ in range(count):
        sim.step()
        assert all(math.isfinite(v) for v in sim.state)
        energies.append(sim.energy(sim.state))
    return sim, np.array(energies)


def assert_passive(scene):
    sim, damped = trajectory_energies(scene)
    assert not sim.refused_steps
    # the undamped twin, from the same state with the same step, for as many steps
    free_sim = Simulator(scene.replace(damping=0.0))
    free = [free_sim.energy(free_sim.state)]
    for _ in range(len(damped) - 1):
        free_sim.step()
        free.append(free_sim.energy(free_sim.state))
    free_drift = np.maximum.accumulate(np.maximum(np.array(free) - free[0], 0.0))
    excess = damped - damped[0] - free_drift
    assert excess.max() <= 1e-6, (
        f"energy rose {excess.max():.3g} J above E(0) + the d = 0 drift "
        f"(d = {scene.damping:g}, h = {scene.step_size:g}, {sim.substeps} sub-steps)")


@SETTINGS
@given(q1=angles, q2=angles, u1=speeds, u2=speeds, damping=dampings, h=steps,
       gravity=st.sampled_from([0.0, 9.81]))
def test_damped_unpowered_arm_is_passive_and_finite(q1, q2, u1, u2, damping, h, gravity):
    assert_passive(Scene(initial_positions=(q1, q2), initial_velocities=(u1, u2), damping=damping,
                         step_size=h, gravity=gravity, policy="zero"))


@SETTINGS
@given(masses=st.tuples(st.floats(0.2, 5.0), st.floats(0.2, 5.0)),
       lengths=st.tuples(st.floats(0.3, 3.0), st.floats(0.3, 3.0)),
       com_fraction=st.tuples(st.floats(0.1, 1.0), st.floats(0.1, 1.0)),
       point_masses=st.booleans(), q2=angles, u1=speeds, damping=dampings, h=steps)
def test_passivity_holds_for_other_arms(masses, lengths, com_fraction, point_masses, q2, u1,
                                        damping, h):
    coms = tuple(f * l for f, l in zip(com_fraction, lengths))
    inertias = (0.0, 0.0) if point_masses else tuple(m * l * l / 12 for m, l in zip(masses, lengths))
    try:
        scene = Scene(link_lengths=lengths, link_masses=masses, com_distances=coms,
                      com_inertias=inertias, initial_positions=(0.2, q2),
                      initial_velocities=(u1, 0.0), damping=damping, step_size=h)
    except SceneError:
        return              # refused as degenerate: nothing to simulate
    # where the step resolves the undamped swing: omega^2 <= gravity (k1 + k2) lambda_max(M^-1)
    omega = math.sqrt(9.81 * sum(scene.arm.gravity_coefficients) * worst_stiffness(scene.arm))
    if omega * h < 0.5:
        assert_passive(scene)


@SETTINGS
@given(q=st.tuples(angles, angles), qd=st.tuples(st.floats(-100, 100), st.floats(-100, 100)),
       tau=st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3)),
       masses=st.tuples(st.floats(1e-3, 1e3), st.floats(1e-3, 1e3)),
       lengths=st.tuples(st.floats(0.01, 10.0), st.floats(0.01, 10.0)),
       damping=st.floats(0.0, 1e4))
def test_mass_solve_residual_is_at_rounding_level(q, qd, tau, masses, lengths, damping):
    arm = model.ArmParameters(lengths, masses, tuple(l / 2 for l in lengths),
                              tuple(m * l * l / 12 for m, l in zip(masses, lengths)))
    qdd = model.forward_dynamics(arm, q, qd, tau, 9.81, damping)
    back = model.inverse_dynamics(arm, q, qd, qdd, 9.81, damping)
    m11, m12, m22 = model.mass_matrix(arm, q)
    terms = [*model.velocity_torque(arm, q, qd), *model.gravity_torque(arm, q, 9.81), *tau,
             damping * qd[0], damping * qd[1]]
    scale = (abs(m11) + 2 * abs(m12) + abs(m22)) * (abs(qdd[0]) + abs(qdd[1])) + sum(map(abs, terms))
    assert max(abs(b - t) for b, t in zip(back, tau)) <= 8 * np.finfo(float).eps * scale


@SETTINGS
@given(q=st.tuples(angles, angles), qd=st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3)),
       torque=st.tuples(st.floats(-1e300, 1e300), st.floats(-1e300, 1e300)),
       damping=st.floats(0.0, 1e4), h=steps)
def test_the_state_is_always_finite_even_when_steps_are_refused(q, qd, torque, damping, h):
    sim = Simulator(Scene(initial_positions=q, initial_velocities=qd, policy="constant",
                          constant_torque=torque, damping=damping, step_size=h))
    for _ in range(max(1, min(20, SUBSTEP_BUDGET // sim.substeps))):
        before = sim.state
        sim.step()
        assert all(math.isfinite(v) for v in sim.state)
        assert sim.state == before or not sim.holding
    assert sim.refused_steps == 0 or sim.fault
