"""A switching scene's compiled run (physics/compiled/switch_run.py, switch_kernel.py) takes exactly
the pure-Python path's steps: in one compiled call while nothing can switch, every step in
which anything could handed back to Python. States, energy books, error books (shadow,
controller counts, schedule), switch counts, saturated steps and every message equal the
pure-Python path's bit for bit, on random scenes of every switching structure the presets
have, with rk4 and exponential_rk4. Skipped without numba.
"""
import functools
import os
from unittest import mock

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator

pytest.importorskip("numba")

from physics.test_compiled import books, python_and_compiled  # noqa: E402

EXAMPLES = int(os.environ.get("ARM_SIM_FUZZ_EXAMPLES", 25))   # more by hand: a longer hunt
FUZZ = settings(max_examples=EXAMPLES, deadline=None,
                derandomize=not os.environ.get("ARM_SIM_FUZZ_EXAMPLES"),
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
# switching structures: friction (Stribeck), hard and compliant limits, effort clamps, and
# geared motors with friction, compliant stops, effort and voltage clamps
PRESETS = ("stick_slip", "limit_impact", "compliant_limit", "effort_limited_hold", "geared_arm")
# geared_arm without its effort limits: a large command drives the drivers past 24 V
UNLIMITED = load_scene("geared_arm").replace(effort_limits=None)


def everything(sim):
    return (books(sim), dict(sim.switch_events), sim.saturated_steps, sim.refused_steps,
            sim.substeps_taken, sim.accumulated_error, sim.accuracy.twin.mode,
            sim.switching.mode)


def same_runs(scene, commands, durations, monkeypatch):
    """Both paths through the same runs, the command changed before each; what they leave."""
    python, fast = python_and_compiled(scene, monkeypatch)
    assert fast.kernel.switched is not None and python.kernel is None
    for command, duration in zip(commands, durations):
        for sim in (python, fast):
            sim.set_command(*command)
        assert python.run(duration) == fast.run(duration)
        assert everything(python) == everything(fast)
    return python, fast


@st.composite
def switching_scenes(draw):
    name = draw(st.sampled_from(PRESETS + ("unlimited",)))
    scene = UNLIMITED if name == "unlimited" else load_scene(name)
    slow = scene.step_size < 0.005                 # geared: 1 ms steps
    speed = 1.0 if slow else 4.0
    scene = scene.replace(
        integrator=draw(st.sampled_from(["rk4", "exponential_rk4"])),
        initial_positions=tuple(draw(st.floats(-1.1, 1.1)) for _ in (0, 1)),
        initial_velocities=tuple(draw(st.floats(-speed, speed)) for _ in (0, 1)),
        tolerance=draw(st.sampled_from([5e-5, 1e-7, 0.0])))
    torque = 250.0 if name == "unlimited" else 30.0
    commands = [tuple(draw(st.floats(-torque, torque)) for _ in (0, 1)) for _ in (0, 1)]
    return scene, commands, (0.15, 0.1) if slow else (0.6, 0.4)


@pytest.mark.hunt
@FUZZ
@given(case=switching_scenes())
def test_random_switching_scenes_run_compiled_as_in_python_bit_for_bit(case, monkeypatch):
    scene, commands, durations = case
    same_runs(scene, commands, durations, monkeypatch)


@pytest.mark.parametrize("integrator", ["rk4", "exponential_rk4"])
@pytest.mark.parametrize("name", PRESETS)
def test_every_switching_preset_runs_compiled_as_in_python(name, integrator, monkeypatch):
    scene = load_scene(name).replace(integrator=integrator)
    seconds = 0.4 if scene.step_size < 0.005 else 3.0
    python, _ = same_runs(scene, [(0.0, 0.0), (2.0, -1.0)], [seconds / 2, seconds / 2],
                          monkeypatch)
    assert sum(python.switch_events.values()) > 0


def test_a_driver_past_its_voltage_limit_is_counted_on_the_same_steps(monkeypatch):
    python, _ = same_runs(UNLIMITED, [(0.0, 0.0), (200.0, -60.0), (0.0, 0.0)],
                          [0.05, 0.1, 0.1], monkeypatch)
    assert 0 < python.saturated_steps < 200


def compiled_simulator(scene):
    """A simulator on the compiled path (whatever ARM_SIM_COMPILED says)."""
    with mock.patch.dict(os.environ, {"ARM_SIM_COMPILED": "1"}):
        return Simulator(scene)


def python_steps(sim, seconds):
    """The steps of sim.run(seconds) Python takes (Simulator.step_in_python), not the
    compiled run."""
    taken, step = [], sim.step_in_python
    sim.step_in_python = lambda: (taken.append(sim.steps), step())
    sim.run(seconds)
    del sim.step_in_python
    return taken


def test_steps_in_which_nothing_can_switch_are_not_taken_by_python():
    """geared_arm held from rest: after its first steps (the first estimate, the joints
    sticking) the compiled run takes every step; stick_slip: Python takes the steps around
    its switches, a few per switch."""
    held = compiled_simulator(load_scene("geared_arm"))
    assert len(python_steps(held, 1.0)) <= 10 and held.steps == 1000
    swinging = compiled_simulator(load_scene("stick_slip"))
    taken = python_steps(swinging, 6.0)
    assert len(taken) <= 6 * sum(swinging.switch_events.values()) and swinging.steps == 600


@functools.cache
def dense_check(name):
    """(compiled near, its K, the mode's guard, width, state width) of a preset's mode."""
    sim = compiled_simulator(load_scene(name))
    mode = MODES[name]
    rhs, _, guard, kinds, _ = sim.switching.functions(mode)
    module, K = sim.kernel.switched.steps.module(rhs)
    return module.near, K, guard, sim.switching.width, len(sim.state)


MODES = {"stick_slip": ("+", "-", 0, 0), "limit_impact": ("free", "free", 0, 0),
         "geared_arm": ("stuck", "+", 0, 0, (0, 0, 0, 0))}
near_zero = st.floats(-0.05, 0.05) | st.sampled_from([0.0, 1e-12, -1e-12])


def both_checks(name, y0, y1, dt):
    """(compiled near, dense.ended's answer, whether it re-stepped to a Hermite instant)."""
    from arm_sim_ros.physics.switching.dense import ended
    near, K, guard, width, states = dense_check(name)
    restepped = []

    def step(rhs, y, t):          # the re-step: here only seen, its state y0's (no switch)
        restepped.append(t)
        return y0
    python = ended(step, None, guard, width, y0, y1, dt) is not None or bool(restepped)
    return near(y0, y1, dt, K, np.zeros(8)), python, bool(restepped)


@pytest.mark.hunt
@FUZZ
@given(name=st.sampled_from(sorted(MODES)), dt=st.sampled_from([1e-3, 1e-2]),
       q0=st.tuples(st.floats(-2.05, 2.05), st.floats(-2.05, 2.05)),
       dq=st.tuples(near_zero, near_zero), u0=st.tuples(near_zero, near_zero),
       u1=st.tuples(near_zero, near_zero), currents=st.tuples(st.floats(-9, 9), st.floats(-9, 9)))
def test_the_compiled_dense_check_hands_back_every_sub_step_dense_ended_would_cut(
        name, dt, q0, dq, u0, u1, currents):
    """The compiled run's check of a sub-step (switch_kernel.near) is True exactly where
    dense.ended ends the mode or re-steps to a Hermite instant: the same switching
    functions at the same instants, the same operations (the re-step is left to Python)."""
    states = dense_check(name)[4]
    pad = (0.0,) * (states - 6)
    y0 = (*q0, *u0, *currents, *pad)[:states]
    y1 = (q0[0] + dt * dq[0], q0[1] + dt * dq[1], *u1, *currents, *pad)[:states]
    compiled, python, _ = both_checks(name, y0, y1, dt)
    assert compiled == python


@pytest.mark.parametrize("u1, q1, expected, restepped", [
    ((0.01, -0.01), (0.0, 0.0), True, True),      # joint 1's q̇ dips below 0 and back
    ((-0.01, -0.01), (0.0, 0.0), True, False),    # ... and ends below 0
    ((0.01, -0.01), (1e-4, -1e-4), False, False)])  # moves on, slides on
def test_a_sliding_joints_stop_inside_a_sub_step_is_handed_back(u1, q1, expected, restepped):
    extra = (0.0,) * (dense_check("stick_slip")[4] - 4)
    y0, y1 = (0.0, 0.0, 0.01, -0.01, *extra), (*q1, *u1, *extra)
    assert both_checks("stick_slip", y0, y1, 0.01) == (expected, expected, restepped)
