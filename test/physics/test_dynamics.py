"""The right-hand side is built from exactly the effects a scene calls for."""
import random

import pytest

from arm_sim_ros.physics import dynamics, model
from arm_sim_ros.physics.effects import POLICIES
from arm_sim_ros.physics.stepping.integrators import RK4, compile_step
from arm_sim_ros.physics.scene import Scene, load_scene, preset_names
from arm_sim_ros.physics.simulator import Simulator


class CountingCos:
    def __init__(self):
        self.calls = 0

    def __call__(self, x):
        from math import cos
        self.calls += 1
        return cos(x)


def rhs_cos_calls(monkeypatch, scene):
    counter = CountingCos()
    monkeypatch.setattr(dynamics, "cos", counter)
    sim = Simulator(scene)
    counter.calls = 0
    sim.dynamics.function(0.3, -0.2, 0.1, 0.4)
    return counter.calls


def test_gravity_free_scene_never_evaluates_gravity(monkeypatch):
    # Gravity is the only term that needs cos q1 and cos(q1 + q2); without it only cos q2 runs.
    scene = load_scene("shoulder_torque_no_gravity")
    assert rhs_cos_calls(monkeypatch, scene) == 1
    assert rhs_cos_calls(monkeypatch, scene.replace(gravity=9.81)) == 3
    assert "G1" not in Simulator(scene).dynamics.source


@pytest.mark.parametrize("name, effects, channels", [
    ("release", ("gravity",), ()),
    ("shoulder_torque_no_gravity", ("actuator",), ("work",)),
    ("gravity_compensation_at_rest", ("gravity", "actuator"), ("work",)),
    ("moving_frozen_gravity", ("gravity", "actuator"), ("work",)),
    ("damped_release", ("gravity", "damping"), ("dissipated",)),
    ("downward_equilibrium", ("gravity",), ()),
])
def test_presets_assemble_only_their_effects(name, effects, channels):
    sim = Simulator(load_scene(name))
    assert sim.dynamics.effects == effects
    assert sim.channels == channels
    assert len(sim.state) == 4 + len(channels)
    if "damping" not in effects:
        assert "DAMPING" not in sim.dynamics.source


def test_compensating_absent_gravity_is_no_actuator():
    sim = Simulator(load_scene("release").replace(gravity=0.0, policy="gravity_compensation"))
    assert sim.dynamics.effects == () and sim.channels == ()


@pytest.mark.parametrize("policy", POLICIES)
@pytest.mark.parametrize("gravity, damping", [(0.0, 0.0), (9.81, 0.0), (0.0, 0.4), (3.7, 1.2)])
def test_generated_rhs_equals_model_forward_dynamics(policy, gravity, damping):
    arm = model.ArmParameters(link_lengths=(0.8, 1.2), link_masses=(1.5, 0.7), com_distances=(0.35, 0.6),
                              com_inertias=(0.04, 0.09))
    # policy setpoint: servos on effort, holding the scene's setpoint torques
    servo = ({"servo": {"interface": ["effort", "effort"], "kp": [0.0, 0.0]},
              "setpoint": (0.7, -0.3)} if policy == "setpoint" else {})
    scene = Scene(gravity=gravity, damping=damping, policy=policy, constant_torque=(0.7, -0.3),
                  initial_positions=(0.2, 0.1), **servo,
                  **{name: getattr(arm, name) for name in model.PAIR_FIELDS})
    built = dynamics.build_dynamics(scene)
    extra = (0.0,) * len(built.extra)          # the servo's integrals (unused on effort)
    built.command[:] = [1.5, -2.5]
    rng = random.Random(7)
    for _ in range(20):
        q1, q2, u1, u2 = (rng.uniform(-3, 3) for _ in range(4))
        tau = built.applied_torque((q1, q2))
        out = built.function(q1, q2, u1, u2, *extra)
        expected = model.forward_dynamics(arm, (q1, q2), (u1, u2), tau, gravity, damping)
        assert out[:2] == pytest.approx(expected, rel=1e-12, abs=1e-12)
        rates = dict(zip(built.channels, out[2 + len(extra):]))
        if "work" in rates:
            assert rates["work"] == pytest.approx(tau[0] * u1 + tau[1] * u2, rel=1e-12, abs=1e-12)
        if "dissipated" in rates:
            assert rates["dissipated"] == pytest.approx(damping * (u1 * u1 + u2 * u2), rel=1e-12)


def test_command_policy_holds_the_latest_command():
    sim = Simulator(load_scene("release").replace(policy="command", gravity=0.0))
    sim.set_command(1.0, 0.0)
    sim.run(0.5)
    reference = Simulator(load_scene("shoulder_torque_no_gravity"))
    reference.run(0.5)
    assert sim.state == reference.state


def test_command_plus_gravity_compensation_adds_g():
    sim = Simulator(load_scene("release").replace(policy="command_gravity_compensation"))
    sim.set_command(0.5, -0.25)
    g = model.gravity_torque(sim.arm, (0.0, 0.0), 9.81)
    assert sim.sample().tau == pytest.approx((g[0] + 0.5, g[1] - 0.25), abs=1e-15)


def test_rk4_tableau_compiles_to_the_explainers_update():
    # One RK4 step of the generated code against the explainer's update rule written out by hand.
    sim = Simulator(load_scene("damped_release"))
    f, h, y = sim.dynamics.function, 0.01, (0.3, -0.4, 1.0, -2.0, 0.0)

    def slope(s):
        a1, a2, r = f(s[0], s[1], s[2], s[3])
        return (s[2], s[3], a1, a2, r)

    def offset(s, k, scale):
        return tuple(x + scale * dx for x, dx in zip(s, k))

    k1 = slope(y)
    k2 = slope(offset(y, k1, h / 2))
    k3 = slope(offset(y, k2, h / 2))
    k4 = slope(offset(y, k3, h))
    by_hand = tuple(y[i] + h * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]) / 6 for i in range(5))
    assert compile_step(RK4, 1)(f, y, h) == pytest.approx(by_hand, rel=1e-15, abs=1e-16)


def test_every_preset_loads_and_runs_its_duration():
    for name in preset_names():
        scene = load_scene(name)
        assert scene.description
        sim = Simulator(scene)
        sim.run(scene.duration)
        assert sim.time == pytest.approx(scene.duration, abs=1e-12)


def test_simulated_time_is_steps_times_step_size():
    sim = Simulator(load_scene("release").replace(step_size=0.001))
    for _ in range(1000):
        sim.step()
    assert sim.time == 1000 * 0.001


def test_scene_tolerances_reach_the_embedded_pair():
    # One 0.5 s publish step, so the tolerances alone decide the internal sub-steps.
    def run(rtol, atol):
        sim = Simulator(load_scene("release").replace(integrator="dopri5", step_size=0.5,
                                                      rtol=rtol, atol=atol))
        sim.run(0.5)
        return sim.state

    reference = run(1e-13, 1e-14)
    error = {tol: max(abs(a - b) for a, b in zip(run(tol, tol), reference)) for tol in (1e-4, 1e-9)}
    assert error[1e-9] < error[1e-4] / 1000
    with pytest.raises(Exception, match="rtol = 0.0 must be at least 1e-14"):
        load_scene("release").replace(rtol=0.0)
