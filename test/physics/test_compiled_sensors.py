"""Sensors and a control loop inside the compiled run (compiled/sensed.py, draws.py): the same
readings, torques, states and books as the pure-Python path, bit for bit, with no step
taken in Python; and the compiled draws are numpy's own."""
from __future__ import annotations

import random
from math import pi

import numpy as np
import pytest

from arm_sim_ros.physics.compiled import build, draws
from arm_sim_ros.physics.compiled.sensed import Sensed
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.sensing.noise import BLOCK, normals
from arm_sim_ros.physics.simulator import Simulator, recorded_row

pytest.importorskip("numba")

CONTRACT = {"seed": 7, "rate": 500.0, "position_resolution": [2 * pi / 4096] * 2,
            "position_noise": [1e-4, 1e-4], "velocity": "differences", "delay": 0.002}
TRUE_VELOCITY = {"seed": 2**40 + 3, "rate": 250.0, "position_noise": [2e-4, 0.0],
                 "position_offset": [0.01, -0.02], "velocity_noise": [1e-3, 3e-3],
                 "delay": 0.003}
RELEASE = load_scene("release").replace(step_size=1e-3)
HOLD = load_scene("servo_hold").replace(estimate="off", tolerance=0.0)


def off(scene):
    return scene.replace(estimate="off", tolerance=0.0)


SCENES = {
    "readings, estimated": RELEASE.replace(sensors=CONTRACT),
    "readings, true velocity": off(RELEASE).replace(sensors=TRUE_VELOCITY),
    "compensation loop": off(load_scene("moving_gravity_compensation")).replace(
        step_size=1e-3, sensors=CONTRACT),
    "commanded, believed payload, delayed": off(RELEASE).replace(
        policy="command_gravity_compensation", controller_model={"payload_mass": 0.3},
        sensors=TRUE_VELOCITY, command_delay=0.004),
    "servo, delayed": HOLD.replace(sensors=CONTRACT, command_delay=0.001),
    "servo velocity and effort": HOLD.replace(
        sensors=TRUE_VELOCITY, command_delay=0.002, policy="command",
        servo=dict(HOLD.servo, interface=["velocity", "effort"])),
    "servo at its rate, limited": off(load_scene("servo_reach")).replace(
        sensors=CONTRACT, command_delay=0.002, effort_limits=[30.0, 20.0],
        servo=dict(load_scene("servo_reach").servo, rate=500.0, integral_limit=[5.0, 2.0])),
}


def python_and_compiled(scene, monkeypatch):
    monkeypatch.setenv("ARM_SIM_COMPILED", "0")
    python = Simulator(scene)
    monkeypatch.setenv("ARM_SIM_COMPILED", "1")
    fast = Simulator(scene)
    taken = []
    fast.step_in_python = lambda step=fast.step_in_python: (taken.append(fast.steps), step())
    return python, fast, taken


def seen(sim, largest):
    return (sim.state, sim.readings, sim.joint_torque(), largest, repr(sim.accumulated_error),
            sim.steps, sim.substeps_taken)


@pytest.mark.parametrize("name", SCENES)
def test_a_sensed_run_is_compiled_and_equals_pythons_bit_for_bit(name, monkeypatch):
    python, fast, taken = python_and_compiled(SCENES[name], monkeypatch)
    results = []
    for sim in (python, fast):
        first = sim.run(0.3)
        sim.set_command(0.5, -0.25, {("velocity", 0): 0.2} if "servo velocity" in name else None)
        results.append((seen(sim, first), seen(sim, sim.run(0.2))))
    assert results[0] == results[1]
    assert taken == []                        # every step in compiled runs


@pytest.mark.parametrize("name", ["servo, delayed", "commanded, believed payload, delayed",
                                  "readings, true velocity"])
def test_a_sensed_run_stepped_one_call_at_a_time_equals_pythons(name, monkeypatch):
    """Simulator.step (the node's tick, a closed loop's step), with the readings, the torque
    and a recording's row read and a command given between steps: Python's, bit for bit.
    The readings and the loop stay in the compiled run's arrays from step to step (packed
    once: a read between steps is taken there, nothing unpacked and packed again)."""
    packed, pack = [], Sensed.pack
    monkeypatch.setattr(Sensed, "pack", lambda self, *args: (packed.append(1), pack(self, *args)))
    python, fast, taken = python_and_compiled(SCENES[name], monkeypatch)
    for n in range(200):
        for sim in (python, fast):
            if n == 100 and "servo" in name:
                sim.set_command(0.0, 0.0, {("position", 1): 0.5})
            elif "commanded" in name:
                sim.set_command(0.01 * (n % 7), -0.02 * (n % 5))
            sim.step()
        assert (python.state, python.readings, python.joint_torque(), recorded_row(python)) == \
            (fast.state, fast.readings, fast.joint_torque(), recorded_row(fast))
    assert taken == [] and len(packed) == 1


def draws_module():
    """A module of the compiled draws, and many(seed, stream, joint, indices) over them."""
    return build.load("import numpy as np\nfrom math import exp, log1p\nfrom numba import njit\n"
                      + draws.source() + '''
@njit(cache=True)
def many(seed, stream, joint, indices):
    R = np.zeros((1, 10), dtype=np.uint64)
    R[0, 0] = NEVER_BLOCK
    out = np.empty(len(indices))
    for k in range(len(indices)):
        out[k] = normal(R, 0, seed, stream, joint, indices[k])
    return out
''')


def test_the_compiled_draws_are_numpys_bit_for_bit_tails_included():
    many, pick = draws_module().many, random.Random(46)
    tails = 0
    for _ in range(24):
        seed = pick.choice([0, 1, 7, 2**32 - 1, 2**32, 2**63 - 1, pick.getrandbits(63)])
        stream, joint, block = pick.randint(0, 1), pick.randint(0, 1), pick.choice([0, 3, 2**33])
        want = normals(seed, stream, joint, block)
        got = many(seed, stream, joint, np.arange(block * BLOCK, (block + 1) * BLOCK))
        assert np.array_equal(got.view(np.uint64), want.view(np.uint64)), (seed, block)
        tails += int((np.abs(want) > 3.6541528853610088).sum())   # the ziggurat's tail
    assert tails > 0


def test_a_compiled_draw_depends_on_its_index_alone_in_any_order():
    many = draws_module().many
    indices = np.array([5, 4, 2047, 1024, 3, 5, 10**6, 0])
    want = [float(normals(9, 1, 0, k // BLOCK)[k % BLOCK]) for k in indices]
    assert many(9, 1, 0, indices).tolist() == want
