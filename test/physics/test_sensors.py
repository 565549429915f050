"""Sensors and command latency (physics/sensing/): each statement of issue 37's contract, one
test each. The readings are what /joint_states carries; test/node/test_sensors_node.py
checks that the node publishes these very numbers, and the truth beside them."""
from __future__ import annotations

from math import pi

import numpy as np
import pytest

from arm_sim_ros.physics import model
from arm_sim_ros.physics.effects.servo import servo_of
from arm_sim_ros.physics.scene import Scene, SceneError, load_scene
from arm_sim_ros.physics.sensing.noise import BLOCK, POSITION, VELOCITY, normals
from arm_sim_ros.physics.simulator import Simulator

from physics.test_servo import books_close

COUNTS_4096 = 2 * pi / 4096           # rad per count: the contract's encoder
CONTRACT = {"seed": 7, "rate": 500.0, "position_resolution": [COUNTS_4096] * 2,
            "position_noise": [1e-4, 1e-4], "position_offset": [0.0, 0.0],
            "velocity": "differences", "delay": 0.002}
AT_REST = Scene(gravity=0.0, step_size=1e-3)      # q = 0, q̇ = 0 for ever: a reading is its error
SWINGING = load_scene("release").replace(step_size=1e-3, tolerance=0.0)


def readings(sim, steps: int) -> list[tuple]:
    """The readings after each of `steps` steps."""
    out = []
    for _ in range(steps):
        sim.step()
        out.append(sim.readings)
    return out


def truth_and_readings(scene, steps: int):
    sim = Simulator(scene)
    states, read = [sim.state[:4]], [sim.readings]
    for _ in range(steps):
        sim.step()
        states.append(sim.state[:4])
        read.append(sim.readings)
    return states, read


def draw(seed: int, stream: int, joint: int, index: int) -> float:
    """Draw `index` of a joint's stream: a function of (seed, stream, joint, index) alone."""
    return float(normals(seed, stream, joint, index // BLOCK)[index % BLOCK])


# -- the contract's YAML block and its order -------------------------------------------------

def test_the_contracts_block_is_a_scene_and_runs():
    sim = Simulator(SWINGING.replace(sensors=CONTRACT, command_delay=0.001))
    assert sim.scene.sensors["velocity"] == "differences" and sim.scene.command_delay == 0.001
    sim.run(0.2)
    assert all(np.isfinite(sim.readings))


def test_the_measured_position_is_quantise_of_q_plus_offset_plus_noise():
    """Order: quantise(q + offset + noise), quantise(x) = round(x / r) x r, draws by index."""
    r, offset, sigma = (2e-3, 3e-3), (0.01, -0.02), (5e-4, 1e-3)
    sim = Simulator(SWINGING.replace(sensors={"seed": 3, "position_resolution": list(r),
                                              "position_offset": list(offset),
                                              "position_noise": list(sigma)}))
    for k in range(1, 300):
        sim.step()
        q = sim.state[:2]
        expected = [round((q[j] + offset[j] + sigma[j] * draw(3, POSITION, j, k)) / r[j]) * r[j]
                    for j in (0, 1)]
        assert list(sim.readings[:2]) == expected


def test_readings_are_whole_multiples_of_the_resolution():
    states, read = truth_and_readings(SWINGING.replace(sensors=CONTRACT), 500)
    assert len({r[0] for r in read}) > 20            # the arm swings through many counts
    for reading in read:
        for x in reading[:2]:
            counts = round(x / COUNTS_4096)
            assert x == counts * COUNTS_4096


# -- noise ------------------------------------------------------------------------------------

@pytest.mark.parametrize("key, stream", [("position_noise", 0), ("velocity_noise", 2)],
                         ids=["position", "velocity"])
def test_the_noise_has_its_standard_deviation_within_5_percent_over_10000_samples_and_is_white(
        key, stream):
    sigma = (1e-3, 4e-3)
    sim = Simulator(AT_REST.replace(sensors={"seed": 11, key: list(sigma)}))
    x = np.array(readings(sim, 10_000))[:, stream:stream + 2]
    n = len(x)
    for j in (0, 1):
        assert abs(np.std(x[:, j]) / sigma[j] - 1.0) < 0.05
        assert abs(np.mean(x[:, j])) < 4 * sigma[j] / np.sqrt(n)
        e = (x[:, j] - x[:, j].mean()) / x[:, j].std()
        lags = [float(np.mean(e[:-lag] * e[lag:])) for lag in range(1, 51)]
        assert max(map(abs, lags)) < 4 / np.sqrt(n)        # no correlation from step to step
    a, b = ((x[:, j] - x[:, j].mean()) / x[:, j].std() for j in (0, 1))
    assert abs(float(np.mean(a * b))) < 4 / np.sqrt(n)     # nor between the joints


def test_the_same_seed_gives_the_same_readings_and_another_seed_others():
    scene = SWINGING.replace(sensors=CONTRACT | {"velocity": "true", "rate": None,
                                                 "position_resolution": None,
                                                 "velocity_noise": [1e-3, 1e-3]})
    first, again = (readings(Simulator(scene), 400) for _ in range(2))
    other = readings(Simulator(scene.replace(**{"sensors.seed": 8})), 400)
    assert first == again
    assert all(a[k] != b[k] for a, b in zip(first[2:], other[2:]) for k in range(4))


def test_a_draw_depends_on_seed_joint_and_index_only_not_on_how_the_run_is_cut():
    """Pause and step, a run cut into pieces, reads in between: the same readings."""
    scene = SWINGING.replace(sensors=CONTRACT, command_delay=0.001, policy="gravity_compensation")
    whole = Simulator(scene)
    whole.run(0.6)
    pieces = Simulator(scene)
    for duration in (0.001, 0.1, 0.037, 0.2, 0.262):
        pieces.run(duration)
        pieces.readings                         # a read between runs changes nothing
    assert pieces.state == whole.state and pieces.readings == whole.readings


# -- delay, rate and differences -------------------------------------------------------------

def test_a_delayed_reading_equals_the_true_state_delay_earlier_exactly():
    states, read = truth_and_readings(SWINGING.replace(sensors={"delay": 0.003}), 400)
    assert read[:4] == [states[0]] * 4                 # before t = delay: the initial state
    assert all(read[n] == states[n - 3] for n in range(3, len(read)))
    assert states[200] != states[197]


def test_readings_are_sampled_at_the_rate_and_held_in_between():
    states, read = truth_and_readings(SWINGING.replace(sensors={"rate": 250.0}), 400)
    for n, reading in enumerate(read):                 # a sample every 4 steps of 1 ms
        assert reading == states[n - n % 4]


def test_differenced_velocities_equal_the_differences_of_the_measured_positions():
    sensors = CONTRACT | {"rate": 250.0, "delay": 0.0}
    _, read = truth_and_readings(SWINGING.replace(sensors=sensors), 800)
    samples = read[::4]
    assert samples[0][2:] == (0.0, 0.0)                # sample 0 has none before it
    for before, now in zip(samples, samples[1:]):
        assert now[2:] == tuple((p - b) / (1 / 250.0) for p, b in zip(now[:2], before[:2]))
    assert any(s[2] != 0.0 for s in samples)


@pytest.mark.parametrize("sensors, words", [
    ({"position_noise": [-1e-4, 0.0]}, "position_noise[0] = -0.0001 is impossible"),
    ({"velocity_noise": [0.0, -1.0]}, "velocity_noise[1] = -1 is impossible"),
    ({"position_resolution": [0.0, 1e-3]}, "position_resolution[0] = 0 is impossible"),
    ({"position_resolution": [1e-3, -1e-3]}, "position_resolution[1] = -0.001 is impossible"),
    ({"delay": 0.0025}, "sensors.delay = 0.0025 s is 2.5 steps"),
    ({"rate": 300.0}, "sensors.rate = 300 Hz samples every 3.33333 steps"),
    ({"rate": 2000.0}, "sensors.rate = 2000 Hz samples every 0.5 steps"),
    ({"velocity": "estimated"}, "sensors.velocity = 'estimated' is not one of differences, true"),
    ({"seed": 1.5}, "sensors.seed = 1.5 is impossible"),
    ({"velocity": "differences", "velocity_noise": [1e-3, 0.0]}, "velocity_noise is for"),
    ({"latency": 0.1}, "sensors.latency is not a key of sensors"),
], ids=["negative noise", "negative velocity noise", "zero resolution", "negative resolution",
        "delay between steps", "rate not whole steps", "rate above the step rate",
        "unknown velocity", "fractional seed", "velocity noise with differences", "unknown key"])
def test_bad_sensors_are_refused_in_one_line(sensors, words):
    with pytest.raises(SceneError) as refused:
        Scene(step_size=1e-3, sensors=sensors)
    assert words in str(refused.value) and "\n" not in str(refused.value)


@pytest.mark.parametrize("delay, words", [(0.0015, "command_delay = 0.0015 s is 1.5 steps"),
                                          (-0.001, "command_delay = -0.001 s must be >= 0")])
def test_a_command_delay_that_is_not_whole_steps_is_refused(delay, words):
    with pytest.raises(SceneError, match=words):
        Scene(step_size=1e-3, command_delay=delay)


# -- the default costs nothing ----------------------------------------------------------------

def test_a_scene_without_sensors_gets_no_sensing_and_reads_the_state():
    sim = Simulator(SWINGING)
    assert sim.sensing is None and sim.dynamics.command is sim.dynamics.given
    sim.run(0.1)
    assert sim.readings == sim.state[:4]


def test_sensors_that_model_nothing_read_the_state_exactly():
    plain, named = Simulator(SWINGING), Simulator(SWINGING.replace(sensors={"seed": 5}))
    for _ in range(200):
        plain.step()
        named.step()
        assert named.readings == named.state[:4] == plain.state[:4]
    assert named.sensing.readings is None and named.sensing.loop is None


# -- who reads the readings --------------------------------------------------------------------

def servo_on(sensors=None, **extra):
    scene = load_scene("servo_hold").replace(**extra)
    return Simulator(scene if sensors is None else scene.replace(sensors=sensors))


def test_a_servo_reads_a_1024_count_encoder_and_hunts_where_on_the_exact_state_it_rests():
    encoder = {"position_resolution": [2 * pi / 1024] * 2, "velocity": "differences"}
    motions = []
    for sim in (servo_on(), servo_on(encoder)):
        sim.run(2.0)
        angles = [s[0] for s in truth_and_readings_from(sim, 1000)]
        motions.append(max(angles) - min(angles))
    exact, counted = motions
    assert exact < 1e-9                                # the exact servo rests
    assert counted > 2 * pi / 1024                     # a limit cycle of counts


def truth_and_readings_from(sim, steps):
    out = []
    for _ in range(steps):
        sim.step()
        out.append(sim.state[:4])
    return out


def test_a_servo_samples_the_reading_by_its_own_law():
    sim = servo_on(CONTRACT | {"delay": 0.0, "rate": None})
    joint_servo = servo_of(sim.dynamics)
    for _ in range(300):
        reading, state = sim.readings, sim.state
        law = joint_servo.law((*reading, *state[4:]), torque_only=True)
        sim.step()
        assert tuple(sim.dynamics.command) == tuple(law)   # what acted over the step


@pytest.mark.parametrize("controller_model", [None, {"payload_mass": 0.3}],
                         ids=["true gravity", "controller model"])
def test_gravity_compensation_reads_the_readings(controller_model):
    scene = load_scene("gravity_compensation_at_rest").replace(
        step_size=1e-3, controller_model=controller_model,
        sensors={"position_offset": [0.02, -0.01], "position_noise": [1e-3, 1e-3]})
    sim = Simulator(scene)
    arm = scene.links.with_payload(0.3) if controller_model else scene.arm
    for _ in range(200):
        reading = sim.readings
        sim.step()
        assert tuple(sim.dynamics.command) == model.gravity_torque(arm, reading[:2],
                                                                   scene.gravity)


@pytest.mark.parametrize("extra", [
    {},
    {"effort_limits": (25.0, 20.0)},
    {"damping": 0.3},
    {"motors": {"gear_ratio": [100.0, 50.0], "rotor_inertia": [1.81e-5, 1.81e-5],
                "resistance": [0.573, 0.573], "inductance": [0.301e-3, 0.301e-3],
                "torque_constant": [0.0404, 0.0404], "voltage_limit": [10.0, 10.0]}},
    {"servo": None, "policy": "command_gravity_compensation", "controller_model": {
        "payload_mass": 0.2}},
], ids=["servo", "effort_limits", "damping", "voltage_limit", "compensation"])
def test_the_books_close_as_without_sensors(extra):
    """Whatever the drive commands from its readings is booked as `work`: the balance closes
    to the bound it closes to without sensors (test_servo.books_close)."""
    scene = load_scene("servo_reach").replace(**extra, sensors=CONTRACT, command_delay=0.002)
    sim = Simulator(scene)
    if scene.servo is None:
        sim.set_command(3.0, -1.0)
    books_close(sim, 1500)
    assert sim.channel_values(sim.state)["work"] != 0.0


@pytest.mark.parametrize("name, extra", [
    ("servo_reach", {}),
    ("servo_reach", {"damping": 0.3}),
    ("payload_release", {"policy": "command_gravity_compensation",
                         "controller_model": {"payload_mass": 0.1}}),
], ids=["servo", "damped servo", "compensation"])
def test_what_the_drive_commands_from_its_readings_acts_and_is_booked_as_a_command_is(name,
                                                                                     extra):
    """The torques a drive computed from its readings, given step by step to the same arm as
    commands, move it and fill its books bit for bit as they did: sensors change what is
    commanded, nothing of how it acts or is booked."""
    scene = load_scene(name).replace(**extra, step_size=1e-3)
    looped = Simulator(scene.replace(sensors=CONTRACT, command_delay=0.002))
    looped.set_command(2.0, -1.0)
    replay = Simulator(scene.replace(servo=None, policy="command", controller_model=None))
    for _ in range(800):
        looped.step()
        replay.set_command(*looped.dynamics.command)    # what acted over that step
        replay.step()
        assert looped.state[:4] == replay.state[:4]
        assert looped.channel_values(looped.state) == replay.channel_values(replay.state)
        assert looped.residual() == replay.residual()


# -- command latency ---------------------------------------------------------------------------

COMMANDED = SWINGING.replace(policy="command")


def test_a_command_acts_exactly_command_delay_later():
    """A command given at t with command_delay d moves the arm bit for bit as the same
    command given at t + d without a delay."""
    delayed, direct = Simulator(COMMANDED.replace(command_delay=0.005)), Simulator(COMMANDED)
    for n in range(300):
        if n == 100:
            delayed.set_command(4.0, -2.0)
        if n == 105:
            direct.set_command(4.0, -2.0)
        delayed.step()
        direct.step()
        assert delayed.state == direct.state
    assert delayed.state[:2] != Simulator(COMMANDED).state[:2]


def test_commands_act_in_order_none_lost():
    sim = Simulator(COMMANDED.replace(command_delay=0.005))
    acted = []
    for n in range(120):
        if 100 <= n < 103:                    # three commands on three steps in a row
            sim.set_command(float(n), 0.0)
        sim.step()
        acted.append(sim.dynamics.command[0])
    assert acted[:105] == [0.0] * 105
    assert acted[105:108] == [100.0, 101.0, 102.0] and acted[108:] == [102.0] * 12


def servo_without_integral(**scene):
    return load_scene("servo_hold").replace(**{"servo.ki": [0.0, 0.0]}, **scene)


def test_a_servo_set_point_acts_command_delay_later_through_the_servos_law():
    """The torque acting at step n is the servo's law at the reading and the set-points of
    step n - d (d = command_delay in steps)."""
    sim = Simulator(servo_without_integral(sensors=CONTRACT, command_delay=0.003))
    joint_servo, seen = servo_of(sim.dynamics), []
    for n in range(300):
        if n == 150:
            sim.set_command(0.0, 0.0, {("position", 0): 0.35})
        seen.append(joint_servo.law((*sim.readings, *sim.state[4:]), torque_only=True))
        sim.step()
        if n >= 3:
            assert tuple(sim.dynamics.command) == tuple(seen[n - 3])
    assert seen[149][0] != seen[150][0]              # the new set-point, computed at 150


def test_before_t_equals_command_delay_the_torque_of_t_0_acts():
    sim = Simulator(load_scene("gravity_compensation_at_rest").replace(
        step_size=1e-3, command_delay=0.004))
    held = tuple(sim.dynamics.command)
    assert held == model.gravity_torque(sim.arm, sim.scene.initial_positions, sim.scene.gravity)
    sim.run(0.01)
    assert max(abs(v) for v in sim.state[2:4]) < 1e-9     # held at rest throughout


# -- live changes ------------------------------------------------------------------------------

def test_a_live_change_of_the_noise_goes_on_in_the_same_stream_never_repeating_it():
    """At rest a reading is σ x its draw: after σ doubles at step 500, each reading is twice
    what the run that kept σ read at that step (index 500 on, not 0 again)."""
    scene = AT_REST.replace(sensors={"seed": 4, "position_noise": [1e-3, 1e-3]})
    kept, changed = Simulator(scene), Simulator(scene)
    for n in range(1000):
        if n == 500:
            changed.change_scene(scene.replace(**{"sensors.position_noise": [2e-3, 2e-3]}))
        kept.step()
        changed.step()
        if n >= 500:
            assert changed.readings[:2] == tuple(2 * v for v in kept.readings[:2])


def test_sensors_switched_off_and_on_live_go_on_at_the_index_where_they_were():
    noisy = AT_REST.replace(sensors={"seed": 4, "position_noise": [1e-3, 1e-3]})
    sim = Simulator(noisy)
    sim.run(0.1)                                      # samples 0..100 taken
    sim.change_scene(noisy.replace(sensors={"seed": 4}))
    sim.run(0.1)
    assert sim.readings == sim.state[:4]
    sim.change_scene(noisy)                           # sample 101 now, at step 200
    assert sim.readings[0] == 1e-3 * draw(4, POSITION, 0, 101)


def test_a_delay_grown_live_holds_the_reading_and_a_shrunk_one_skips_ahead():
    scene = SWINGING.replace(sensors={"delay": 0.002})
    sim, states, read = Simulator(scene), [], []
    for n in range(300):
        if n == 100:
            sim.change_scene(scene.replace(**{"sensors.delay": 0.005}))
        if n == 200:
            sim.change_scene(scene.replace(**{"sensors.delay": 0.001}))
        states.append(sim.state[:4])
        read.append(sim.readings)
        sim.step()
    age = [n - states.index(r) for n, r in enumerate(read)]
    assert age[2:101] == [2] * 99                     # 2 steps old
    assert age[101:104] == [3, 4, 5] and age[104:200] == [5] * 96   # held, then 5 old
    assert age[200:] == [1] * 100                     # skipped ahead to 1 step old


def test_a_command_delay_shrunk_live_loses_no_command_given_before():
    sim = Simulator(COMMANDED.replace(command_delay=0.010))
    acted = []
    for n in range(140):
        if n in (100, 101, 102):
            sim.set_command(float(n), 0.0)
        if n == 103:                                   # 10 steps -> 1: three in flight
            sim.change_scene(sim.scene.replace(command_delay=0.001))
        sim.step()
        acted.append(sim.dynamics.command[0])
    firsts = [acted.index(v) for v in (100.0, 101.0, 102.0)]
    assert firsts == [110, 111, 112]          # in flight: each when it was due, in order
    sim.set_command(7.0, 0.0)                 # given now: one step later
    sim.step()
    assert sim.dynamics.command[0] == 102.0
    sim.step()
    assert sim.dynamics.command[0] == 7.0


def test_a_command_delay_grown_live_holds_the_acting_torque_and_repeats_nothing():
    sim = Simulator(COMMANDED.replace(command_delay=0.002))
    acted = []
    for n in range(60):
        sim.set_command(float(n), 0.0)                 # a new command every step
        if n == 30:
            sim.change_scene(sim.scene.replace(command_delay=0.006))
        sim.step()
        acted.append(sim.dynamics.command[0])
    assert acted == sorted(acted)                      # never back to an older one
    assert acted[33:35] == [acted[32]] * 2 and acted[-1] == 53.0


def test_batch_rollouts_refuse_sensors_and_a_command_delay_in_one_line():
    from arm_sim_ros.physics.batch import Batch
    for scene in (SWINGING.replace(sensors=CONTRACT), COMMANDED.replace(command_delay=0.001)):
        with pytest.raises(SceneError, match="batch rollouts cannot run (sensors|a command_delay)"):
            Batch(scene, count=2)


@pytest.mark.parametrize("scene", [
    SWINGING.replace(sensors=CONTRACT),
    COMMANDED.replace(sensors=CONTRACT, command_delay=0.002),   # (a servo scene stays on
    load_scene("moving_gravity_compensation").replace(step_size=1e-3, sensors=CONTRACT),
], ids=["readings", "delayed command", "compensation loop"])      # Python's path: build.py)
def test_the_compiled_step_reads_the_acting_torque_as_python_does_bit_for_bit(scene,
                                                                             monkeypatch):
    """Under a control loop the drive's code reads the acting torque where a command policy
    reads its command: the compiled step takes it, and agrees with Python's bit for bit."""
    pytest.importorskip("numba")
    monkeypatch.setenv("ARM_SIM_COMPILED", "0")
    python = Simulator(scene)
    monkeypatch.setenv("ARM_SIM_COMPILED", "1")
    fast = Simulator(scene)
    assert (python.path, fast.path) == ("python", "compiled (numba)")
    for sim in (python, fast):
        sim.run(0.5)
    assert python.state == fast.state and python.readings == fast.readings
    assert python.accumulated_error == fast.accumulated_error


def test_sensors_named_live_on_a_scene_without_them_read_from_then_on():
    sim = Simulator(SWINGING)
    sim.run(0.1)
    sim.change_scene(SWINGING.replace(sensors={"delay": 0.002}))
    held = sim.state[:4]
    assert sim.readings == held                       # sample 0 now, at t = 0.1 s
    sim.step()
    sim.step()
    assert sim.readings == held
    sim.step()
    assert sim.readings != held


@pytest.mark.parametrize("sensors", [{"position_resolution": [2 * pi / 1024] * 2},
                                     CONTRACT | {"velocity": "true"}],
                         ids=["1024 counts", "the contract's, velocity true"])
def test_the_error_estimate_follows_a_servo_that_holds_an_arm_up_on_its_readings(sensors):
    """Without the loop the held arm falls away from any neighbour: the shadow, driven by
    the motion's torques alone, was lost within 5 s (2e-3 rad at 5.3 s) though every step
    was accurate to 1e-14. With a controller of its own it stays with the motion."""
    sim = Simulator(load_scene("servo_hold").replace(sensors=sensors, command_delay=0.001))
    sim.run(8.0)
    assert sim.accumulated_error < 1e-8
    assert not any("no longer follows" in e.message for e in sim.events)
