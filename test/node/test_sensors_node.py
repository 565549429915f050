"""Sensors on the node (issue 37): /joint_states carries the readings and ~/true_joint_states
the truth at the same stamps, bit for bit what the offline simulator reads (core, dds; rclpy
in test_node_rclpy.py where it imports); pause and step, lockstep and the transport do not
change the stream; `sensors.*` and `command_delay` are parameters, live, a bad one refused
in one line and the node unchanged."""
from __future__ import annotations

import logging

import pytest

from arm_sim_ros.interface import TRUE_JOINT_STATES
from arm_sim_ros.node.core import ArmSimCore
from arm_sim_ros.node.main import main as node_main
from arm_sim_ros.node.params.parameters import SPECS, ParameterRefused, resolve_parameters
from arm_sim_ros.node.wire import messages as msg
from arm_sim_ros.physics.simulator import Simulator

SENSORS = {"sensors.seed": 7, "sensors.rate": 500.0,
           "sensors.position_resolution": [0.0015339807878856412] * 2,
           "sensors.position_noise": [1e-4, 1e-4], "sensors.velocity": "differences",
           "sensors.delay": 0.002, "command_delay": 0.001}
NODE = {"scene": "servo_hold", "publish_rate": 250.0} | SENSORS     # 4 steps of 1 ms a tick


def make_core(**overrides):
    return ArmSimCore(resolve_parameters(NODE | overrides), logging.getLogger("test_sensors"),
                      wall_clock=lambda: 0.0, start_stamp_ns=0)


def offline(core, ticks: int, changes=(), commands=()):
    """[(readings, state)] after each tick of a Simulator of the node's own scene; `changes`
    {tick: scene} changed live and `commands` {tick: torque} given before that tick."""
    sim, out = Simulator(core.config.scene), []
    for k in range(ticks):
        if k in dict(changes):
            sim.change_scene(dict(changes)[k])
        if k in dict(commands):
            sim.set_command(*dict(commands)[k])
        for _ in range(core.config.steps_per_tick):
            sim.step()
        out.append((list(sim.readings), list(sim.state[:4])))
    return out


def published(data):
    return (data.position + data.velocity, data.truth.position + data.truth.velocity)


def test_joint_states_carry_the_readings_and_the_truth_goes_beside_at_the_same_stamp():
    core = make_core()
    for k, (reading, state) in enumerate(offline(core, 150)):
        data = core.tick(0.0)
        assert published(data) == (reading, state)
        assert data.truth.stamp_ns == data.stamp_ns == (k + 1) * 4_000_000
        assert data.effort == data.truth.effort
    assert reading != state


def test_without_sensors_there_is_no_truth_topic_and_joint_states_is_the_state():
    core = ArmSimCore(resolve_parameters({"scene": "servo_hold"}), logging.getLogger("t"),
                      wall_clock=lambda: 0.0, start_stamp_ns=0)
    data = core.tick(0.0)
    assert data.truth is None and data.position == list(core.sim.state[:2])


def test_step_simulation_lockstep_and_pauses_leave_the_stream_as_it_was():
    expected = offline(make_core(), 40)
    stepped, locked, paused = make_core(), make_core(lockstep=True), make_core()
    got = {"stepped": [], "locked": [], "paused": []}
    assert len(locked.lockstep.take()) == 1                   # the state awaiting its answer
    for k in range(40):
        got["stepped"].append(stepped.step_tick())             # StepSimulation, one by one
        locked.on_command([0.0, 0.0])                          # each command ticks once
        got["locked"] += locked.lockstep.take()
        paused.paused = k % 3 == 0                             # paused ticks: time stands still
        held = paused.tick(0.0)
        paused.paused = False
        got["paused"].append(paused.tick(0.0) if k % 3 == 0 else held)
        assert held is not None
    for name, states in got.items():
        assert [published(d) for d in states] == expected, name


def test_sensor_parameters_are_declared_with_unit_and_meaning_and_change_live():
    for name in ("sensors.seed", "sensors.rate", "sensors.position_resolution",
                 "sensors.position_noise", "sensors.position_offset", "sensors.velocity",
                 "sensors.velocity_noise", "sensors.delay", "command_delay"):
        assert SPECS[name].description and SPECS[name].when.startswith("live"), name
    assert "rad per count" in SPECS["sensors.position_resolution"].description
    core = make_core()
    for _ in range(50):
        core.tick(0.0)
    changed = {"sensors.position_noise": [3e-4, 3e-4], "command_delay": 0.003}
    assert core.set_parameters(changed) == list(changed)
    assert core.sim.steps == 200                               # carried on, not restarted
    base = core.config.scene
    expected = offline(make_core(), 100, {50: base})
    for k in range(50):
        data = core.tick(0.0)
        assert published(data) == expected[50 + k]             # the stream goes on


@pytest.mark.parametrize("name, value, words", [
    ("sensors.position_noise", [-1e-4, 0.0], "position_noise[0] = -0.0001 is impossible"),
    ("sensors.position_resolution", [0.0, 1e-3], "position_resolution[0] = 0 is impossible"),
    ("sensors.delay", 0.0025, "2.5 steps"),
    ("sensors.rate", 300.0, "1/rate must be a whole number of steps"),
    ("command_delay", 0.0015, "a delay must be a whole number of steps"),
    ("sensors.velocity", "maybe", "is not one of differences, true"),
], ids=["negative noise", "zero resolution", "delay", "rate", "command delay", "velocity"])
def test_a_bad_sensor_parameter_is_refused_in_one_line_and_changes_nothing(name, value, words):
    core = make_core()
    core.tick(0.0)
    before, sim = core.config, core.sim
    with pytest.raises(ParameterRefused) as refused:
        core.set_parameters({name: value})
    assert words in str(refused.value) and "\n" not in str(refused.value)
    assert refused.value.name == name and core.config is before and core.sim is sim
    with pytest.raises(ParameterRefused, match=words.replace("[", r"\[").replace("]", r"\]")):
        resolve_parameters(NODE | {name: value})                # at start too


def test_a_bad_sensor_parameter_on_the_command_line_exits_2_in_one_line(capsys):
    assert node_main(["--transport", "dds", "--ros-args", "-p", "scene:=servo_hold",
                      "-p", "sensors.delay:=0.0025"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "sensors.delay" in err[0] and "2.5 steps" in err[0]


def test_dds_readings_and_truth_are_bit_identical_to_offline():
    """A torque command on the dds wire, read back: the readings on /joint_states and the
    truth on /arm_sim/true_joint_states are the offline simulator's, bit for bit."""
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    from node.test_node_dds import start, wait_until

    node, peer = start(160, **(NODE | {"scene": "release", "step_size": 0.001,
                                       "policy": "command_gravity_compensation"}))
    p = peer.participant
    truth = DataReader(p, Topic(p, msg.ros_topic(TRUE_JOINT_STATES), msg.JointState),
                       qos=msg.default_qos(msg.JointState, depth=1000))
    commands = {0: (0.0, 0.0), 5: (0.5, -0.2), 30: (-1.0, 0.3)}
    expected = offline(node.core, 60, commands=commands)
    for k in range(60):
        if k in commands and k:
            peer.send(node, commands[k])
        node.tick()
        if k == 0:        # the truth's writer comes with the first truth: matched from then
            wait_until(lambda: msg.matched(truth), "no ~/true_joint_states on loopback")
    readings = peer.read(peer.joint_states, 60, msg.JointState)
    truths = []            # the first one too, where discovery was quicker than the write
    wait_until(lambda: truths.extend(m for m in truth.take(N=1000)
                                     if isinstance(m, msg.JointState)) or truths and
               truths[-1].header.stamp == readings[-1].header.stamp, "no last true joint state")
    first = 60 - len(truths)
    assert [list(m.position) + list(m.velocity) for m in readings] == [r for r, _ in expected]
    assert [list(m.position) + list(m.velocity) for m in truths] == [
        s for _, s in expected[first:]]
    assert [m.header.stamp for m in truths] == [m.header.stamp for m in readings[first:]]
    assert readings[-1].position != truths[-1].position
    node.close()


@pytest.mark.parametrize("every", [False, True], ids=["set (dds)", "every parameter (rclpy)"])
def test_a_physics_that_cannot_be_built_at_start_blames_the_key_that_was_set(every):
    """Issue 47: an offset of 1e308 read in counts of 1e-300 rad overflows as the sensors are
    built; the refusal blamed `policy` (the first parameter) at start. rclpy hands over every
    parameter, set or not: the one blamed is one whose value is not the scene's default."""
    from arm_sim_ros.node.params.parameters import scene_defaults

    hostile = {"sensors.position_offset": [1e308, 1e308],
               "sensors.position_resolution": [1e-300, 1e-300]}
    given = (scene_defaults("release") if every else {}) | {"scene": "release"} | hostile
    with pytest.raises(ParameterRefused) as refused:
        ArmSimCore(resolve_parameters(given), logging.getLogger("test_sensors"),
                   wall_clock=lambda: 0.0, start_stamp_ns=0)
    assert refused.value.name in hostile, str(refused.value)
