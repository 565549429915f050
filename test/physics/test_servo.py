"""Joint servos (effects/servo.py): position and velocity set-points under gravity, effort
limits with anti-windup, windings, the energy books, bumpless switching and refusals."""
from __future__ import annotations

import pytest

from arm_sim_ros.physics.effects.servo import change_scene, servo_of
from arm_sim_ros.physics.scene import Scene, SceneError, load_scene
from arm_sim_ros.physics.simulator import Simulator

GAINS = {"kp": [200.0, 100.0], "ki": [300.0, 150.0], "kd": [30.0, 10.0]}
WINDINGS = {"gear_ratio": [100.0, 50.0], "rotor_inertia": [1.81e-5, 1.81e-5],
            "resistance": [0.573, 0.573], "inductance": [0.301e-3, 0.301e-3],
            "torque_constant": [0.0404, 0.0404]}


def reach(**scene):
    return Scene(**({"gravity": 9.81, "policy": "setpoint", "setpoint": (0.5, -0.3),
                     "servo": GAINS, "step_size": 1e-3} | scene))


def books_close(sim, steps, tolerance=1e-6):
    largest = 0.0
    for _ in range(steps):
        sim.step()
        largest = max(largest, abs(sim.residual()))
    inputs, losses = sim.books(sim.state)
    assert largest <= tolerance * max(1.0, abs(sim.energy(sim.state)), abs(inputs), abs(losses))


def test_a_position_set_point_is_reached_within_a_milliradian_under_gravity():
    sim = Simulator(load_scene("servo_reach"))
    sim.run(4.0)
    assert abs(sim.state[0] - 0.5) < 1e-3 and abs(sim.state[1] + 0.3) < 1e-3
    assert max(abs(v) for v in sim.state[2:4]) < 1e-3


def test_the_hold_scene_keeps_its_initial_pose_exactly():
    sim = Simulator(load_scene("servo_hold"))
    sim.run(1.0)
    assert sim.state[0:2] == pytest.approx((0.3, 0.6), abs=1e-9)


def test_a_velocity_set_point_is_held_within_a_milliradian_per_second_in_steady_state():
    # Shoulder turning at 1 rad/s, elbow held in position, gravity fed forward.
    sim = Simulator(Scene(gravity=9.81, policy="command_gravity_compensation", step_size=1e-3,
                          servo={"interface": ["velocity", "position"], "kp": [50.0, 100.0],
                                 "ki": [100.0, 100.0], "kd": [0.0, 15.0]}))
    servo_of(sim.dynamics).setpoint[2] = 1.0
    sim.run(3.0)
    worst = 0.0
    for _ in range(2000):           # two more seconds: a full turn and more
        sim.step()
        worst = max(worst, abs(sim.state[2] - 1.0), abs(sim.state[1]))
    assert worst < 1e-3


def test_a_velocity_joint_takes_its_own_gains_and_never_kd():
    """velocity_kp and velocity_ki on velocity joints (kp and ki where not given); a position
    joint keeps kp, ki and kd; a velocity joint never acts on kd (it would act on the
    acceleration its torque causes), so one scene's gains serve either interface."""
    gains = GAINS | {"velocity_kp": [30.0, 10.0], "velocity_ki": [200.0, 100.0]}
    both = servo_of(Simulator(reach(servo=gains | {"interface": ["velocity", "position"]}))
                    .dynamics)
    assert (both.kp, both.ki, both.kd) == ((30.0, 100.0), (200.0, 150.0), (0.0, 10.0))
    assert both.tracking == (200.0 / 30.0, 150.0 / 100.0)
    plain = servo_of(Simulator(reach(servo=GAINS | {"interface": ["velocity", "velocity"]}))
                     .dynamics)
    assert (plain.kp, plain.ki, plain.kd) == ((200.0, 100.0), (300.0, 150.0), (0.0, 0.0))
    # the same law as a velocity PI without kd: a scene with kd set turns just as one without
    runs = []
    for kd in ([30.0, 10.0], [0.0, 0.0]):
        sim = Simulator(reach(policy="command_gravity_compensation", servo=gains | {
            "interface": ["velocity", "velocity"], "kd": kd}))
        servo_of(sim.dynamics).setpoint[2] = 0.5
        sim.run(1.0)
        runs.append(sim.state)
    assert runs[0] == runs[1] and abs(runs[0][2] - 0.5) < 1e-2     # turning at 0.5 rad/s


def overshoot_under_effort_limits(tracking):
    """(peak shoulder torque, peak integral, overshoot) reaching 0.5 rad against 25 N m."""
    sim = Simulator(reach(effort_limits=(25.0, 20.0), servo=GAINS | {"tracking": tracking}))
    peak_torque, peak_integral, overshoot = 0.0, 0.0, 0.0
    for _ in range(6000):
        sim.step()
        peak_torque = max(peak_torque, abs(sim.joint_torque()[0]))
        peak_integral = max(peak_integral, abs(sim.state[4]))
        overshoot = max(overshoot, sim.state[0] - 0.5)
    assert abs(sim.state[0] - 0.5) < 1e-3
    return peak_torque, peak_integral, overshoot


def test_effort_limits_cut_the_request_and_the_back_calculation_stops_the_windup():
    # The shoulder asks for 100 N m at first against a 25 N m limit; with the tracking rate
    # ~0 (no anti-windup) the integral winds up to ~49 N m and overshoots 0.17 rad.
    torque, integral, overshoot = overshoot_under_effort_limits(None)
    _, wound_integral, wound_overshoot = overshoot_under_effort_limits([1e-9, 1e-9])
    assert torque == pytest.approx(25.0)
    assert integral < 0.6 * wound_integral and overshoot < 0.5 * wound_overshoot


def test_the_integral_clamp_bounds_the_integral_torque():
    sim = Simulator(reach(servo=GAINS | {"integral_limit": [5.0, 5.0]}))
    sim.run(6.0)
    # 5 N m cannot hold the shoulder's ~18 N m: it sags until kp e makes up the rest
    error = 0.5 - sim.state[0]
    assert sim.joint_torque()[0] - GAINS["kp"][0] * error == pytest.approx(5.0, abs=1e-4)
    assert error > 0.05


@pytest.mark.parametrize("extra", [{}, {"effort_limits": (25.0, 20.0)}, {"damping": 0.3},
                                   {"motors": WINDINGS},
                                   {"motors": WINDINGS | {"voltage_limit": [10.0, 10.0]}}],
                         ids=["servo", "effort_limits", "damping", "windings", "voltage_limit"])
def test_the_books_close_with_the_servos_work(extra):
    sim = Simulator(reach(**extra))
    books_close(sim, 1500)
    work = sim.channel_values(sim.state)["work"]
    assert work != 0.0
    kinds = dict(zip(sim.channels, sim.dynamics.channel_kinds))
    assert kinds["work"] == ("transfer" if "motors" in extra else "input")


def test_with_windings_the_servo_drives_the_voltage_and_still_reaches():
    sim = Simulator(reach(motors=WINDINGS))
    sim.run(4.0)
    assert abs(sim.state[0] - 0.5) < 1e-3 and abs(sim.state[1] + 0.3) < 1e-3
    assert sim.extra == ("integral1", "integral2", "i1", "i2")
    assert sim.channel_values(sim.state)["copper_loss"] > 0.0


def test_a_scene_without_a_servo_builds_exactly_the_code_it_built_before():
    for name in ("release", "gravity_compensation_at_rest", "motor_windings_hold"):
        source = Simulator(load_scene(name)).dynamics.source
        assert "SP[" not in source and "integral" not in source and "ts1" not in source


@pytest.mark.parametrize("switch", [("position", "velocity"), ("position", "effort"),
                                    ("velocity", "position"), ("effort", "position")])
def test_switching_interface_live_is_bumpless(switch):
    before, after = switch
    gains = {"kp": [200.0, 100.0], "ki": [100.0, 100.0], "kd": [0.0, 0.0] if "velocity" in switch
             else [30.0, 10.0]}
    scene = reach(policy="command_gravity_compensation",
                  servo=gains | {"interface": [before, "position"]}, initial_velocities=(0.4, 0.0))
    sim = Simulator(scene)
    sim.run(0.2)
    torque = sim.joint_torque()
    change_scene(sim, scene.replace(**{"servo.interface": [after, "position"]}))
    assert sim.joint_torque() == pytest.approx(torque, abs=1e-9)
    q = sim.state[0]
    sim.run(0.01)                                    # and no kick in the next steps
    assert abs(sim.state[0] - q) < 0.01


@pytest.mark.parametrize("scene, message", [
    (dict(policy="setpoint"), "policy setpoint needs a servo"),
    (dict(policy="gravity_compensation", servo=GAINS), "servo needs policy"),
    (dict(policy="setpoint", servo={"kp": [1, 1], "velocity_kp": [1, -1]}),
     "servo.velocity_kp[1] = -1 is impossible"),
    (dict(policy="setpoint", servo={"interface": ["torque", "position"], "kp": [1, 1]}),
     "servo.interface[0] = 'torque' is not one of position, velocity, effort"),
    (dict(policy="setpoint", servo={"interface": "position", "kp": [1, 1]}),
     "servo.interface needs two names"),
    (dict(policy="setpoint", servo={"kp": [1, -1]}), "servo.kp[1] = -1 is impossible"),
    (dict(policy="setpoint", servo={"ki": [1, 1]}), "servo needs servo.kp"),
    (dict(policy="setpoint", servo={"kp": [1, 1], "integral_limit": [0, 1]}),
     "servo.integral_limit[0] = 0 is impossible"),
])
def test_impossible_servo_settings_are_refused_in_one_line(scene, message):
    with pytest.raises(SceneError) as refused:
        Scene(**scene)
    assert message in str(refused.value) and "\n" not in str(refused.value)


def test_the_command_line_sets_servo_keys_and_runs_a_set_point_policy():
    scene = load_scene("servo_hold").with_text_overrides(
        ["servo.interface=velocity,position", "servo.kd=0,15", "policy=setpoint",
         "setpoint=0.5,0.6", "gravity=0"])
    assert scene.servo["interface"] == ("velocity", "position")
    sim = Simulator(scene)
    sim.run(2.0)
    assert sim.state[2] == pytest.approx(0.5, abs=1e-3)
