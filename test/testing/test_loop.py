"""A controller under test in process (arm_sim_ros/testing/loop.py): the Python callable
against the scene's own Simulator, through its sensors and command_delay, adding nothing
to the physics; deterministic; bad answers refused in one line."""
import numpy as np
import pytest

from arm_sim_ros.physics.scene import SceneError
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.testing.loop import ControllerError, closed_loop
from arm_sim_ros.testing.loop import scene_for

TARGET = np.array([0.5, -0.3])
NO_GRAVITY = {"gravity": 0.0, "step_size": 0.001}
SENSORS = NO_GRAVITY | {"sensors.seed": 3, "sensors.position_resolution": [0.0015, 0.0015],
                        "sensors.position_noise": [1e-4, 1e-4], "sensors.velocity": "differences",
                        "sensors.delay": 0.002, "command_delay": 0.001}


def pd(reading):
    return 60.0 * (TARGET - reading.q) - 12.0 * reading.qd


def test_a_pd_controller_reaches_its_target_in_ten_lines(arm):
    trace = arm.run(pd, "release", seconds=3.0, overrides=NO_GRAVITY, reference=TARGET)
    assert trace.settle_time() < 2.0
    assert trace.overshoot() < 0.1          # rad
    assert trace.steady_state_error() < 1e-3
    assert trace.peak_torque() <= 60.0 * 0.5 + 1e-9     # the first answer: kp x the move
    assert trace.books_closed()


def test_the_loop_adds_nothing_to_the_physics():
    """The scene's Simulator stepped by hand with the same answers: the same states, bit
    for bit, the torques the commands, the readings the truth (no sensors)."""
    trace = closed_loop(pd, "release", 0.5, overrides=NO_GRAVITY)
    sim = Simulator(scene_for("release", NO_GRAVITY))
    states = [sim.state[:4]]
    for _ in range(500):
        sim.set_command(*pd(type("R", (), {"q": np.array(sim.state[0:2]),
                                           "qd": np.array(sim.state[2:4])})))
        sim.step()
        states.append(sim.state[:4])
    np.testing.assert_array_equal(np.column_stack([trace.q, trace.qd]), np.array(states))
    np.testing.assert_array_equal(trace.measured_q, trace.q)
    np.testing.assert_array_equal(trace.tau[1:-1], trace.command[:-2])   # held over each step
    assert np.isnan(trace.command[-1]).all()                  # the last state: not answered


def test_the_controller_reads_the_sensors_and_its_answer_acts_command_delay_later():
    trace = closed_loop(pd, "release", 0.5, overrides=SENSORS)
    assert not np.array_equal(trace.measured_q, trace.q)
    assert np.abs(trace.measured_q - trace.q).max() < 0.01
    # the answer given at step k acts from step k + 1 (command_delay 1 ms = one step)
    np.testing.assert_array_equal(trace.tau[2:], trace.command[:-2])


def test_a_closed_loop_with_sensors_is_the_same_bit_for_bit_every_time():
    first, second = (closed_loop(pd, "release", 0.3, overrides=SENSORS) for _ in range(2))
    np.testing.assert_array_equal(first.rows(), second.rows())


def test_the_controller_runs_at_its_own_rate():
    calls = []

    def counted(reading):
        calls.append(reading.t)
        return pd(reading)
    trace = closed_loop(counted, "release", 0.1, rate=100.0, overrides=NO_GRAVITY)
    assert calls == pytest.approx([0.01 * k for k in range(10)])
    assert np.all(trace.command[1:10] == trace.command[0])      # held for ten steps
    with pytest.raises(SceneError, match="not a whole number of steps"):
        closed_loop(counted, "release", 0.1, rate=300.0, overrides=NO_GRAVITY)


@pytest.mark.parametrize("answer,why", [((float("nan"), 0.0), "finite"), ((1.0,), "two"),
                                        ("fast", "two"), (None, "two")])
def test_an_answer_the_arm_cannot_take_is_one_line_naming_when(answer, why):
    def broken(reading):
        return answer if reading.t >= 0.05 else (0.0, 0.0)
    with pytest.raises(ControllerError, match=f"at t = 0.05.* {why}") as caught:
        closed_loop(broken, "release", 0.2, overrides=NO_GRAVITY)
    assert caught.value.trace is not None and caught.value.trace.t[-1] == pytest.approx(0.05)


def test_set_points_drive_the_scene_servo():
    """command="position": the servo of servo_reach takes the answers as its set-points."""
    trace = closed_loop(lambda reading: TARGET, "servo_reach", 3.0, command="position",
                        reference=TARGET)
    assert trace.steady_state_error() < 2e-3
    assert np.all(trace.command[:-1] == TARGET)


def test_a_hold_needs_a_band_for_its_settle_time():
    trace = closed_loop(lambda r: (0.0, 0.0), "release", 0.1, overrides=NO_GRAVITY,
                        reference=[0.0, 0.0])
    with pytest.raises(ValueError, match="band"):
        trace.settle_time()
    assert trace.settle_time(band=1e-9) == 0.0
