"""Discrete joint servos (servo.rate, effects/servo.py): samples from t = 0 (a step split at
those inside it), the torque held between them, RK4's order kept, the books closed, the
error estimate, bumpless switches, refusals."""
from __future__ import annotations

import pytest

from arm_sim_ros.physics.batch import Batch
from arm_sim_ros.physics.effects.servo import change_scene, servo_of
from arm_sim_ros.physics.scene import Scene, SceneError, load_scene
from arm_sim_ros.physics.simulator import Simulator

GAINS = {"kp": [200.0, 100.0], "ki": [300.0, 150.0], "kd": [30.0, 10.0]}
WINDINGS = {"gear_ratio": [100.0, 50.0], "rotor_inertia": [1.81e-5, 1.81e-5],
            "resistance": [0.573, 0.573], "inductance": [0.301e-3, 0.301e-3],
            "torque_constant": [0.0404, 0.0404]}


def reach(rate, **scene):
    return Scene(**({"gravity": 9.81, "policy": "setpoint", "setpoint": (0.5, -0.3),
                     "servo": GAINS | {"rate": rate}, "step_size": 1e-3} | scene))


@pytest.mark.parametrize("rate, step_size", [(100.0, 1e-3), (1000.0, 1e-3), (100.0, 1e-2)],
                         ids=["100 Hz, 1 ms steps", "1 kHz, 1 ms steps (every step)",
                              "100 Hz, 10 ms steps (every step)"])
def test_a_discrete_servo_reaches_its_set_point_within_a_milliradian_under_gravity(rate,
                                                                                  step_size):
    sim = Simulator(reach(rate, step_size=step_size))
    sim.run(4.0)
    assert abs(sim.state[0] - 0.5) < 1e-3 and abs(sim.state[1] + 0.3) < 1e-3
    assert max(abs(v) for v in sim.state[2:4]) < 1e-3


def test_a_discrete_velocity_servo_holds_the_commanded_velocity_in_steady_state():
    sim = Simulator(Scene(gravity=9.81, policy="command_gravity_compensation", step_size=1e-3,
                          servo={"interface": ["velocity", "position"], "kp": [50.0, 100.0],
                                 "ki": [100.0, 100.0], "kd": [0.0, 15.0], "rate": 200.0}))
    servo_of(sim.dynamics).setpoint[2] = 1.0
    sim.run(3.0)
    worst = 0.0
    for _ in range(2000):
        sim.step()
        worst = max(worst, abs(sim.state[2] - 1.0), abs(sim.state[1]))
    assert worst < 1e-3


def test_the_torque_is_held_between_samples_and_each_sample_is_the_law_at_its_state():
    sim = Simulator(reach(100.0))            # a sample every 10 steps of 1 ms
    joint_servo = servo_of(sim.dynamics)
    assert sim.sampled is joint_servo and joint_servo.every == 10
    held = []
    for n in range(200):
        if n % 10 == 0:                      # at t = k/rate: what the law asks there
            law = joint_servo.law(sim.state, torque_only=True)
        before = sim.channel_values(sim.state)["work"]
        sim.step()
        torque = sim.joint_torque()
        held.append(torque)
        assert torque == tuple(law)
        # the work of the step is the held torque's: ∫ τ·q̇ dt = τ·Δq for a constant τ
        # (RK4 integrates both with the same weights)
        work = sim.channel_values(sim.state)["work"] - before
        assert work == pytest.approx(torque[0] * (sim.state[0] - q0[0]) + torque[1] * (
            sim.state[1] - q0[1]), rel=1e-9, abs=1e-15) if n else True
        q0 = sim.state[0:2]
    changes = [n for n in range(1, 200) if held[n] != held[n - 1]]
    assert changes == list(range(10, 200, 10))


@pytest.mark.parametrize("extra", [{}, {"effort_limits": (25.0, 20.0)}, {"damping": 0.3},
                                   {"motors": WINDINGS | {"voltage_limit": [10.0, 10.0]}}],
                         ids=["servo", "effort_limits", "damping", "voltage_limit"])
def test_the_books_close_with_the_held_torques_work(extra):
    sim = Simulator(reach(100.0, **extra))
    largest = 0.0
    for _ in range(1500):
        sim.step()
        largest = max(largest, abs(sim.residual()))
    inputs, losses = sim.books(sim.state)
    assert sim.channel_values(sim.state)["work"] != 0.0
    assert largest <= 1e-6 * max(1.0, abs(sim.energy(sim.state)), abs(inputs), abs(losses))


def test_a_step_with_a_sample_is_checked():
    """A sample changes the held torque, as a new command does: its step is checked. Left
    to the schedule, a sample into a saturating driver's windings went unmeasured, and the
    books closed to 1.4e-4 J where they close to 3e-7 (the test above, voltage_limit)."""
    sim = Simulator(reach(100.0))
    for n in range(100):
        sim.step()
        if n % 10 == 0:                      # a sample at the step's start
            assert sim.accuracy.since == sim.steps, n


def test_rk4_keeps_its_fourth_order_with_the_torque_held():
    # The same discrete servo (100 Hz) at steps of 2, 1 and 0.5 ms against 0.125 ms: the
    # right-hand side is smooth between samples, so halving the step cuts the error ~16x.
    def final(h):
        sim = Simulator(reach(100.0, step_size=h, initial_velocities=(2.0, -3.0)))
        sim.run(0.5)
        return sim.state[0:4]

    reference = final(1.25e-4)
    errors = [max(abs(a - b) for a, b in zip(final(h), reference)) for h in (2e-3, 1e-3, 5e-4)]
    assert errors[0] / errors[1] > 12 and errors[1] / errors[2] > 12


def test_samples_are_on_the_grid_from_time_zero_after_a_reset():
    sim = Simulator(reach(100.0))
    first = sim.joint_torque()               # what the sample at t = 0 holds, before a step
    sim.run(0.013)
    sim.reset()
    assert sim.joint_torque() == first
    sim.step()
    assert sim.joint_torque() == first


@pytest.mark.parametrize("switch", [("position", "velocity"), ("position", "effort"),
                                    ("velocity", "position"), ("effort", "position")])
@pytest.mark.parametrize("rates", [(100.0, 100.0), (None, 100.0), (100.0, None)],
                         ids=["discrete", "to discrete", "to continuous"])
@pytest.mark.parametrize("when", [0.2, 0.204], ids=["on a sample", "between samples"])
def test_switching_interface_live_with_a_rate_is_bumpless(switch, rates, when):
    before, after = switch
    # a velocity gain of 200 N m s/rad sampled at 100 Hz is past the sampled loop's stability
    # (kp T / inertia > 2 on the shoulder): 50
    velocity = "velocity" in switch
    gains = {"kp": [50.0 if velocity else 200.0, 100.0], "ki": [100.0, 100.0],
             "kd": [0.0, 0.0] if velocity else [30.0, 10.0]}
    scene = reach(rates[0], policy="command_gravity_compensation", initial_velocities=(0.4, 0.0),
                  servo=gains | {"interface": [before, "position"], "rate": rates[0]})
    sim = Simulator(scene)
    sim.run(when)
    torque = sim.joint_torque()
    change_scene(sim, scene.replace(**{"servo.interface": [after, "position"],
                                       "servo.rate": rates[1]}))
    assert sim.joint_torque() == pytest.approx(torque, abs=1e-9)
    if rates[1] and when == 0.2:   # the switched joint's first sample, at once: no jump
        sim.step()
        assert sim.joint_torque()[0] == pytest.approx(torque[0], abs=1e-9)
    q = sim.state[0]
    sim.run(0.01)                                    # a sample on the way, and no kick
    assert abs(sim.state[0] - q) < 0.01


@pytest.mark.parametrize("rate, step_size, message", [
    (2e5, 1e-3, "servo.rate = 200000 Hz samples 200 times in each step of 0.001 s, each "
                "splitting it; at most 100: lower the rate or the step_size"),
    (0.0, 1e-3, "servo.rate = 0 is impossible: it must be positive (Hz)"),
    (-100.0, 1e-3, "servo.rate = -100 is impossible"),
    ("fast", 1e-3, "servo.rate must be a number (Hz)"),
    (1e-12, 1e-3, "servo.rate = 1e-12 Hz samples less than once in 1e9 steps"),
])
def test_impossible_rates_are_refused_in_one_line(rate, step_size, message):
    with pytest.raises(SceneError) as refused:
        reach(rate, step_size=step_size)
    assert message in str(refused.value) and "\n" not in str(refused.value)


@pytest.mark.parametrize("rate, split, whole", [(300.0, 1e-3, 1 / 3000), (1000.0, 1e-2, 1e-3),
                                                (150.0, 1e-2, 1 / 1500)],
                         ids=["300 Hz in 1 ms steps", "1 kHz in 10 ms steps",
                              "150 Hz in 10 ms steps"])
def test_samples_inside_a_step_split_it_there(rate, split, whole):
    # The same servo with its samples inside the steps (the step split at each) and on step
    # boundaries (steps a whole fraction of its period): the same motion, to RK4's accuracy.
    def final(h):
        sim = Simulator(reach(rate, step_size=h, initial_velocities=(2.0, -3.0)))
        sim.run(1.0)
        return sim.state[0:4], sim.residual()

    (inside, residual), (boundary, _) = final(split), final(whole)
    assert max(abs(a - b) for a, b in zip(inside, boundary)) < 1e-8
    assert abs(residual) < 1e-6


def test_the_torque_changes_at_the_samples_inside_a_step_and_is_held_between():
    sim = Simulator(reach(300.0))            # samples at k/300 s: inside steps of 1 ms
    joint_servo = servo_of(sim.dynamics)
    assert joint_servo.samples_in(0) == (True, [])
    at_start, inside = joint_servo.samples_in(3)       # 3 ms to 4 ms: the sample at 10/3 ms
    assert not at_start and inside == pytest.approx([1 / 300 - 3e-3])
    assert joint_servo.samples_in(10) == (True, [])     # 10 ms = 3/300 s: on the boundary
    held = []
    for _ in range(30):
        sim.step()
        held.append(sim.joint_torque())
    changes = [n for n in range(1, 30) if held[n] != held[n - 1]]
    assert changes == [3, 6, 10, 13, 16, 20, 23, 26]   # the steps that hold a sample


def test_a_continuous_servo_builds_the_code_it_built_before():
    sim = Simulator(reach(None))
    assert sim.sampled is None and "HELD" not in sim.dynamics.source
    assert "KI1 * e1" in sim.dynamics.source


def test_batch_rollouts_refuse_a_discrete_servo_in_one_line():
    with pytest.raises(SceneError, match="batch rollouts cannot run a discrete servo"):
        Batch(reach(100.0), count=2)


@pytest.mark.parametrize("rate", [100.0, 300.0], ids=["on the steps", "inside the steps"])
def test_the_global_error_estimate_follows_a_discrete_servo_within_a_factor_of_ten(rate):
    # The shadow (shadow.py) samples its own state: the true motion's servo sees the true
    # state. Sampled the motion's instead, it drifted open-loop to 9e-2 rad in 4 s.
    def run(h):
        sim = Simulator(reach(rate, step_size=h, effort_limits=(120.0, 60.0)))
        every, states = round(1e-3 / h), []
        for n in range(round(2.0 / h)):
            sim.step()
            if (n + 1) % every == 0:
                states.append(sim.state[0:4])
        return states, sim.accumulated_error

    motion, estimate = run(1e-3)
    reference, _ = run(1.25e-4)
    true = max(abs(a - b) for s, r in zip(motion, reference) for a, b in zip(s, r))
    assert true / 10 < estimate < true * 10


def test_a_discrete_servo_with_friction_limits_and_windings_closes_its_books():
    # Switches located inside the pieces the samples make (events.py), a saturating driver.
    sim = Simulator(reach(300.0, friction={"coulomb": [2.0, 1.0], "static": [3.0, 1.5]},
                          joint_limits={"lower": [-0.2, -0.25], "upper": [1.0, 1.0]},
                          motors=WINDINGS | {"voltage_limit": [10.0, 10.0]}))
    largest = 0.0
    for _ in range(1500):
        sim.step()
        largest = max(largest, abs(sim.residual()))
    inputs, losses = sim.books(sim.state)
    assert sim.fault is None and sum(sim.switch_events.values()) > 0
    assert largest <= 1e-6 * max(1.0, abs(sim.energy(sim.state)), abs(inputs), abs(losses))


@pytest.mark.parametrize("rate, said", [(140.0, True), (160.0, False)])
def test_a_rate_too_slow_for_the_velocity_gains_is_said_in_one_line(rate, said):
    # servo_hold's kd (52, 17 N m s/rad) held for T through M(q)⁻¹ reaches 2 at 153.8 Hz:
    # below, the sampled loop limit-cycles; above, it settles.
    sim = Simulator(load_scene("servo_hold").with_text_overrides([f"servo.rate={rate}"]))
    warnings = [e.message for e in sim.events if e.kind == "servo"]
    assert len(warnings) == said and all("\n" not in w for w in warnings)
    if said:
        assert "raise the rate above 153.8 Hz or lower the gains" in warnings[0]
    joint_servo = servo_of(sim.dynamics)
    joint_servo.setpoint[0:2] = [0.8, -0.2]
    sim.run(3.0)
    assert (abs(sim.state[0] - 0.8) > 1e-3) == said


@pytest.mark.parametrize("books", ["refused plan", "dopri5"])
def test_a_discrete_servo_without_a_global_estimate_samples_and_holds(books):
    """Books with no shadow (a plan past the planner's bound holds the arm; dopri5 has no
    global estimate): the servo still samples, where it once raised AttributeError out of
    a node's tick (found by a live fuzz on rclpy)."""
    scene = load_scene("servo_hold")
    scene = scene.replace(servo=dict(scene.servo, rate=100.0),
                          **({"damping": 1e200} if books == "refused plan"
                             else {"integrator": "dopri5", "step_size": 0.01}))
    sim = Simulator(scene)
    for _ in range(5):
        sim.step()
    assert all(v == v for v in sim.state)
    assert (sim.fault is not None) == (books == "refused plan")
