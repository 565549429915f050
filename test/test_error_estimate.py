"""Issue 14 parts 1-2: every step's local error estimate, its sum, and the tolerance.

The accumulated estimate is compared with the true error (the largest |q, qd| difference at
any step) against scipy's DOP853 at rtol = atol = 1e-13; for scenes that switch modes
(friction, limits, clamps: events.py) against the same event-located stepper at h/64,
since DOP853 knows no modes (RK4 at h/64 is 64^4 ~ 1.7e7 times closer). Within a factor of
10 where the errors do not grow along the motion; where they do, it is documented below.
Every scene runs at the default tolerance unless named otherwise.
"""
from math import isnan

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from arm_sim_ros.physics.accuracy import DEFAULT_TOLERANCE
from arm_sim_ros.physics.scene import Scene, load_scene
from arm_sim_ros.physics.simulator import Simulator

FINE = 16   # reference sub-division for switching scenes (and a tolerance of 1e-11)


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
    fine = Simulator(scene.replace(step_size=h / FINE, tolerance=1e-11, max_substeps=20000))
    states = [sim.state]
    for _ in range(steps):
        for _ in range(FINE):
            fine.step()
        states.append(fine.state)
    return states


def ratio(scene, duration):
    """(accumulated estimate / the largest true error, the largest true error)."""
    sim = Simulator(scene)
    steps = scene.steps_for(duration)
    expected = reference(scene, sim, steps)
    true = 0.0
    for k in range(1, steps + 1):
        sim.step()
        true = max(true, max(abs(a - b) for a, b in zip(sim.state[:4], expected[k][:4])))
    return sim.accumulated_error / true, true


HOLDS = {
    "release": (load_scene("release"), 2.0),
    "damped_release": (load_scene("damped_release"), 2.0),
    "shoulder_torque_no_gravity": (load_scene("shoulder_torque_no_gravity"), 2.0),
    "per_joint_damping": (load_scene("per_joint_damping"), 2.0),
    "springs_oscillation": (load_scene("springs_oscillation"), 2.0),
    "payload_release": (load_scene("payload_release"), 2.0),
    "wrong_payload_model": (load_scene("wrong_payload_model"), 2.0),
    "geared_release": (load_scene("geared_release"), 2.0),
    "spin_1ms": (spin(0.001), 1.0),
    "spin_10ms": (spin(0.01), 1.0),
    "spin_1ms_estimate_only": (spin(0.001, tolerance=0.0), 1.0),
    "spin_10ms_estimate_only": (spin(0.01, tolerance=0.0), 1.0),
    "spin_damped": (spin(0.001, damping=0.5), 1.0),
    "release_rk38": (load_scene("release").replace(integrator="rk38"), 2.0),
    "release_midpoint_estimate_only": (load_scene("release").replace(integrator="midpoint",
                                                                     tolerance=0.0), 2.0),
    # switching scenes (events.py): smooth steps on the schedule, every step starting with a
    # compliant limit engaged estimated piece by piece, and, when steps are not split,
    # every step with a located switch
    "effort_limited_hold": (load_scene("effort_limited_hold"), 2.0),
}


@pytest.mark.parametrize("name", list(HOLDS))
def test_the_accumulated_estimate_is_within_a_factor_of_10_of_the_true_error(name):
    scene, duration = HOLDS[name]
    r, true = ratio(scene, duration)
    assert true > 1e-12
    assert 0.1 <= r <= 10.0, (name, r, true)


def test_where_it_does_not_hold_it_is_known_and_on_which_side():
    """Open (issue 22, part 4): a sum of local errors is not a global error where the
    motion contracts errors (an attracting hold, a joint that sticks) or maps them through
    a contact's timing (the velocity jumps while the contact lasts). Measured with the
    controller that follows the error both ways; what remains to be built is an error
    propagated along the motion."""
    def r(scene):
        return ratio(scene, 2.0)[0]
    assert 10.0 < r(load_scene("motor_windings_hold")) < 100.0     # attracting hold: over
    assert 10.0 < r(load_scene("stick_slip")) < 100.0               # sticking wipes errors
    assert r(load_scene("compliant_limit")) < 0.1                   # contact timing: under
    assert r(load_scene("limit_impact")) < 0.1                      # impact timing: under
    assert 10.0 < r(load_scene("moving_frozen_gravity").replace(tolerance=0.0)) < 20.0
    assert r(load_scene("moving_frozen_gravity")) < 0.1            # errors grow: under
    # dopri5 reports its 4th-order companion's error for its 5th-order solution: over
    assert 10.0 < r(load_scene("release").replace(integrator="dopri5")) < 20.0


@pytest.mark.parametrize("h", [0.001, 0.01])
def test_the_default_tolerance_keeps_a_fast_spin_honest(h):
    sim = Simulator(spin(h))
    assert sim.scene.tolerance == DEFAULT_TOLERANCE > 0
    start, drift = sim.energy(sim.state), [0.0]
    sim.run(5.0, lambda s: drift.__setitem__(0, max(drift[0], abs(s.energy(s.state) - start))))
    assert drift[0] / start < 1e-6
    assert sim.substeps_taken > 0 and any(e.kind == "substepping" for e in sim.events)
    plain = Simulator(spin(h, tolerance=0.0))
    plain.run(0.5)
    assert plain.substeps_taken == 0 and plain.error_estimate > 0


@pytest.mark.parametrize("name,h,duration", [
    ("release", 0.01, 2.0), ("release", 0.005, 2.0), ("release", 0.0005, 2.0),
    ("shoulder_torque_no_gravity", 0.01, 0.5), ("moving_gravity_compensation", 0.01, 1.0),
    ("moving_frozen_gravity", 0.01, 0.5), ("downward_equilibrium", 0.01, 2.0),
    ("damped_release", 0.01, 2.0)])
def test_the_default_tolerance_leaves_every_explainer_figure_bit_for_bit(name, h, duration):
    runs = []
    for tolerance in (0.0, DEFAULT_TOLERANCE):
        sim = Simulator(load_scene(name).replace(step_size=h, tolerance=tolerance))
        states = []
        sim.run(duration, lambda s: states.append(s.state))
        runs.append(states)
        assert sim.substeps_taken == 0
    assert runs[0] == runs[1]


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
        assert sim.error_estimate > 0 and sim.accumulated_error >= sim.error_estimate
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
