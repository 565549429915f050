"""Issue 14 parts 1-2: every step's local error estimate, its sum, and the tolerance.

The accumulated estimate is compared with the true error against scipy's DOP853 at
rtol = atol = 1e-13 (the largest |q, qd| difference at any step): within a factor of 10
where the errors do not grow along the motion; where they do, it is documented below.
"""
from math import isnan

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from arm_sim_ros.physics.accuracy import SPIN_TOLERANCE
from arm_sim_ros.physics.scene import Scene, load_scene
from arm_sim_ros.physics.simulator import Simulator


def spin(h, tolerance=SPIN_TOLERANCE, **kw):
    """100 rad/s about the shoulder, elbow bent 0.5 rad, gravity off."""
    values = dict(initial_positions=(0.0, 0.5), initial_velocities=(100.0, 0.0), gravity=0.0,
                  step_size=h, tolerance=tolerance)
    return Scene(**(values | kw))


def ratio(scene, duration):
    """(accumulated estimate / the largest true error, the largest true error)."""
    sim = Simulator(scene)
    f, width, h = sim.dynamics.function, 4 + len(sim.extra), scene.step_size
    steps = scene.steps_for(duration)
    times = [k * h for k in range(steps + 1)]
    solution = solve_ivp(lambda t, y: (y[2], y[3], *f(*y[:width])), (0.0, times[-1]),
                         list(sim.state), method="DOP853", t_eval=times, rtol=1e-13, atol=1e-13)
    reference = np.asarray(solution.y).T
    true = 0.0
    for k in range(1, steps + 1):
        sim.step()
        true = max(true, max(abs(a - b) for a, b in zip(sim.state[:4], reference[k][:4])))
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
    "spin_damped": (spin(0.001, damping=0.5), 1.0),
    "release_rk38": (load_scene("release").replace(integrator="rk38"), 2.0),
    "release_midpoint": (load_scene("release").replace(integrator="midpoint"), 2.0),
}


@pytest.mark.parametrize("name", list(HOLDS))
def test_the_accumulated_estimate_is_within_a_factor_of_10_of_the_true_error(name):
    scene, duration = HOLDS[name]
    r, true = ratio(scene, duration)
    assert true > 1e-12
    assert 0.1 <= r <= 10.0, (name, r, true)


def test_where_it_does_not_hold_it_is_known_and_on_which_side():
    # The frozen gravity torque pumps a flailing arm (12 rad/s by 2 s): plain steps hold,
    # just (9.9x); once the tolerance splits its steps after 1.5 s, errors that grow along
    # the motion and peaks between checks make the sum underestimate (0.08x).
    r, _ = ratio(load_scene("moving_frozen_gravity"), 2.0)
    assert 1.0 < r <= 10.0
    r, _ = ratio(load_scene("moving_frozen_gravity").replace(tolerance=SPIN_TOLERANCE), 2.0)
    assert r < 0.1
    # dopri5 reports its 4th-order companion's error for its 5th-order solution: safe,
    # pessimistic (11x on the release).
    r, _ = ratio(load_scene("release").replace(integrator="dopri5"), 2.0)
    assert 10.0 < r < 20.0


@pytest.mark.parametrize("h", [0.001, 0.01])
def test_the_tolerance_keeps_a_fast_spin_honest(h):
    sim = Simulator(spin(h))
    start, drift = sim.energy(sim.state), [0.0]
    sim.run(5.0, lambda s: drift.__setitem__(0, max(drift[0], abs(s.energy(s.state) - start))))
    assert drift[0] / start < 1e-6
    assert sim.substeps_taken > 0 and any(e.kind == "substepping" for e in sim.events)
    plain = Simulator(spin(h, tolerance=0.0))
    plain.run(0.5)
    assert plain.substeps_taken == 0 and plain.error_estimate > 0


@pytest.mark.parametrize("name,h,duration", [
    ("release", 0.01, 2.0), ("release", 0.005, 2.0), ("shoulder_torque_no_gravity", 0.01, 0.5),
    ("moving_gravity_compensation", 0.01, 0.5), ("moving_frozen_gravity", 0.01, 0.5)])
def test_the_spin_tolerance_leaves_every_explainer_figure_bit_for_bit(name, h, duration):
    runs = []
    for tolerance in (0.0, SPIN_TOLERANCE):
        sim = Simulator(load_scene(name).replace(step_size=h, tolerance=tolerance))
        states = []
        sim.run(duration, lambda s: states.append(s.state))
        runs.append(states)
        assert sim.substeps_taken == 0
    assert runs[0] == runs[1]


def test_every_integrator_reports_an_estimate_and_switching_scenes_say_nan():
    for integrator in ("rk4", "rk38", "midpoint", "euler", "semi_implicit_euler", "dopri5"):
        sim = Simulator(load_scene("release").replace(integrator=integrator))
        sim.run(0.5)
        assert sim.error_estimate > 0 and sim.accumulated_error >= sim.error_estimate
        sim.reset()
        assert sim.accumulated_error == 0.0
    sim = Simulator(load_scene("stick_slip"))
    sim.run(0.1)
    assert isnan(sim.error_estimate) and isnan(sim.accumulated_error)


def test_a_negative_tolerance_is_refused():
    from arm_sim_ros.physics.scene import SceneError
    with pytest.raises(SceneError, match="tolerance"):
        load_scene("release").replace(tolerance=-1.0)
