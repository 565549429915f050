"""The compiled path (extra `fast`, numba) takes the same steps as the pure-Python path,
bit for bit: states, energy books, error books, the largest residual. Skipped without numba.
"""
import hashlib
import math
import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from arm_sim_ros.physics.trust import accuracy, controller
from arm_sim_ros.physics.compiled import build as compiled
from arm_sim_ros.physics.scene import load_scene, preset_names
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.physics.stepping import stability
from physics.test_error_estimate import CASES

pytest.importorskip("numba")
if os.environ.get("ARM_SIM_COMPILED") == "0":      # .ci/run's pure-Python pass: its second
    pytest.skip("the compiled path is off (ARM_SIM_COMPILED=0); .ci/run's compiled pass "
                "runs these", allow_module_level=True)

SCENES = {
    "release": load_scene("release"),
    "springs_oscillation": load_scene("springs_oscillation"),
    "moving_gravity_compensation": load_scene("moving_gravity_compensation"),
    "windings_exponential": load_scene("motor_windings_hold").replace(
        integrator="exponential_rk4", initial_velocities=(1.0, -2.0)),
    "payload_damping_command": load_scene("payload_release").replace(
        damping=(0.3, 0.1), policy="command_gravity_compensation"),
    # steps retaken, counts raised and lowered, the estimate lost: each said by Python
    "release_tight": load_scene("release").replace(tolerance=1e-8),
    "release_tolerance_off": load_scene("release").replace(tolerance=0.0),
    "springs_fast_spin": load_scene("springs_oscillation").replace(
        initial_velocities=(30.0, -40.0)),
    # contracting motions (test_error_estimate), at half the step and twice the damping
    # (the same d h Lambda): a new count checked at the next step; near the stability limit,
    # the shadow's local error measured where it is
    **{name: CASES[name][0].replace(step_size=0.01, damping=2 * CASES[name][0].damping)
       for name in ("damped_constant_torque_at_a_new_count",
                    "damped_constant_torque_near_the_stability_limit")},
}


def python_and_compiled(scene, monkeypatch):
    monkeypatch.setenv("ARM_SIM_COMPILED", "0")
    python = Simulator(scene)
    monkeypatch.setenv("ARM_SIM_COMPILED", "1")
    return python, Simulator(scene)


@pytest.mark.parametrize("name", SCENES)
def test_compiled_run_equals_python_run_bit_for_bit(name, monkeypatch):
    python, fast = python_and_compiled(SCENES[name], monkeypatch)
    assert (python.path, fast.path) == ("python", "compiled (numba)")
    for sim in (python, fast):
        sim.set_command(0.7, -0.4)
    for duration in (0.37, 1.0):          # runs that end between checks, then go on
        assert python.run(duration) == fast.run(duration)
        assert python.state == fast.state
        assert python.steps == fast.steps
        assert python.accumulated_error == fast.accumulated_error      # the shadow's too
        assert python.error_estimate == fast.error_estimate
        assert python.substeps_taken == fast.substeps_taken


def books(sim):
    """Everything the error books, the shadow and the divergence check carry on."""
    b, shadow = sim.accuracy, sim.accuracy.shadow
    return (sim.state, sim.steps, sim._sound, sim.energy_in_play, sim.fault, sim.books_fault,
            sim.diverged, b.due, b.since, b.every, b.substeps, b.booked_taken, b.free.previous,
            b.most, b.capped, b.cap, b.error_estimate, shadow.local, shadow.offset,
            shadow.shadow, shadow.largest, shadow.lost, [(e.t, e.message) for e in sim.events])


@pytest.mark.parametrize("name", SCENES)
def test_the_compiled_run_leaves_the_books_as_python_leaves_them(name, monkeypatch):
    """The checks, the controller's counts, the schedule and the divergence checks run in
    the compiled loop; what they carry on, and what they say, is Python's."""
    python, fast = python_and_compiled(SCENES[name], monkeypatch)
    for duration in (0.64, 1.28, 0.05):    # ends on a divergence check, and between
        python.run(duration)
        fast.run(duration)
        assert books(python) == books(fast)
    assert (python.accuracy.shadow.last is python.state) == (
        fast.accuracy.shadow.last is fast.state)


def test_a_smooth_run_is_one_compiled_call_until_something_is_to_be_said(monkeypatch):
    """The checks and the divergence checks are in the compiled loop: Python takes no step
    of a run where nothing is said (a new highest count, a fault)."""
    sim = Simulator(load_scene("moving_gravity_compensation"))
    taken = []
    monkeypatch.setattr(sim, "step_in_python", lambda: taken.append(sim.steps))
    sim.run(3.0)
    assert taken == [] and sim.steps == 300 and sim.state is sim._sound
    assert not [e for e in sim.events if e.kind in ("substepping", "substeps", "accuracy",
                                                    "unpredictable", "fault")]


def test_a_step_that_misses_the_tolerance_is_taken_again_in_the_compiled_loop(monkeypatch):
    """release at tolerance 1e-6: steps where the elbow whips miss it and are taken again
    with more sub-steps, inside the compiled loop; Python takes only the steps that say a
    new highest count."""
    retaken = []
    monkeypatch.setattr(accuracy, "retake", lambda *a: retaken.append(a) or controller.retake(*a))
    python, fast = python_and_compiled(load_scene("release").replace(tolerance=1e-6),
                                       monkeypatch)
    handed, step = [], fast.step_in_python
    monkeypatch.setattr(fast, "step_in_python", lambda: handed.append(fast.steps) or step())
    assert python.run(4.0) == fast.run(4.0)
    assert books(python) == books(fast)
    said = [e for e in fast.events if e.kind in ("substepping", "substeps")]
    assert len(retaken) >= 5 and 0 < len(handed) <= len(said) < len(retaken)


SMOOTH = ("release", "damped_release", "springs_oscillation", "payload_release",
          "moving_frozen_gravity", "motor_windings_hold")


@st.composite
def smooth_runs(draw):
    """A smooth preset from a random state at a random tolerance (steps missed and taken
    again, counts raised and lowered), a new command before each run."""
    scene = drawn_start(draw, load_scene(draw(st.sampled_from(SMOOTH))),
                        [0.0, 1e-9, 1e-7, 5e-5, 1e-3])
    if scene.springs is None and scene.motors is None and draw(st.booleans()):
        # damping up to past RK4's stability limit: steps that barely decay (the shadow's
        # local error measured where it is), then sub-steps
        edge = draw(st.floats(0.3, 1.3)) * stability.RK4_REAL_LIMIT
        scene = scene.replace(damping=edge / (scene.step_size * stability.worst_stiffness(
            scene.arm)))
    commands = [tuple(draw(st.floats(-10.0, 10.0)) for _ in (0, 1)) for _ in (0, 1, 2)]
    return scene, commands


def drawn_start(draw, scene, tolerances, policy="command_gravity_compensation"):
    """`scene` under `policy` from a random pose and speed (slower at a fine step), at a
    tolerance drawn from `tolerances`."""
    speed = 1.0 if scene.step_size < 0.005 else 6.0
    return scene.replace(
        policy=policy,
        initial_positions=tuple(draw(st.floats(-1.5, 1.5)) for _ in (0, 1)),
        initial_velocities=tuple(draw(st.floats(-speed, speed)) for _ in (0, 1)),
        tolerance=draw(st.sampled_from(tolerances)))


def fuzz(examples: int):
    """A fuzz's settings: `examples` derandomized, or ARM_SIM_FUZZ_EXAMPLES drawn afresh."""
    return settings(max_examples=int(os.environ.get("ARM_SIM_FUZZ_EXAMPLES", examples)),
                    deadline=None, derandomize=not os.environ.get("ARM_SIM_FUZZ_EXAMPLES"),
                    suppress_health_check=[HealthCheck.too_slow,
                                           HealthCheck.function_scoped_fixture])


@fuzz(8)      # ARM_SIM_FUZZ_EXAMPLES=200 for a hunt
@given(case=smooth_runs())
def test_random_smooth_runs_leave_the_books_as_python_leaves_them(case, monkeypatch):
    scene, commands = case
    python, fast = python_and_compiled(scene, monkeypatch)
    for command, duration in zip(commands, (0.3, 0.05, 0.47)):
        for sim in (python, fast):
            sim.set_command(*command)
        assert python.run(duration) == fast.run(duration)
        assert books(python) == books(fast)


def test_a_payload_grasped_between_runs_goes_on_from_the_same_books(monkeypatch):
    python, fast = python_and_compiled(SCENES["release"], monkeypatch)
    for sim in (python, fast):
        sim.run(0.3)
        sim.set_payload(0.8)
        sim.run(0.5)
    assert books(python) == books(fast)


def test_books_that_do_not_close_are_found_at_the_check_python_finds_them_at(monkeypatch):
    """A step too coarse for a 30 rad/s spin (tolerance off): the check of every state
    finds the books off at the first step (40 % of the energy in play), on both paths, and
    says it once."""
    scene = load_scene("springs_oscillation").replace(
        step_size=0.05, tolerance=0.0, initial_velocities=(30.0, -30.0))
    python, fast = python_and_compiled(scene, monkeypatch)
    assert python.run(20.0) == fast.run(20.0)
    assert python.books_fault.startswith("at t = 0.05 s the energy books do not close")
    assert books(python) == books(fast)


def test_a_run_with_a_per_step_callback_sees_every_step_and_ends_in_the_same_state(monkeypatch):
    python, fast = python_and_compiled(SCENES["release"], monkeypatch)
    seen = []
    fast.run(0.2, lambda s: seen.append(s.steps))
    python.run(0.2)
    assert seen == list(range(1, 21)) and fast.state == python.state


def test_a_step_that_would_not_be_finite_is_refused_as_on_the_python_path(monkeypatch):
    scene = load_scene("release").replace(initial_velocities=(1e150, 1e150), tolerance=0.0)
    python, fast = python_and_compiled(scene, monkeypatch)
    python.run(0.1)
    fast.run(0.1)
    assert fast.fault == python.fault and fast.fault is not None
    assert fast.state == python.state and fast.refused_steps == python.refused_steps


@pytest.mark.parametrize("name, seconds", [("stick_slip", 1.5), ("geared_arm", 0.1)])
def test_switching_scenes_step_each_modes_compiled_step_bit_for_bit(name, seconds, monkeypatch):
    python, fast = python_and_compiled(load_scene(name), monkeypatch)
    for sim in (python, fast):
        sim.set_command(2.0, -1.0)
    assert python.run(seconds) == fast.run(seconds)
    assert python.state == fast.state and python.switch_events == fast.switch_events
    assert sum(python.switch_events.values()) > 0
    assert python.accumulated_error == fast.accumulated_error


def test_adaptive_steps_stay_on_the_python_path():
    assert Simulator(load_scene("release").replace(integrator="dopri5")).path == "python"


def test_without_it_nothing_is_compiled(monkeypatch):
    monkeypatch.setenv("ARM_SIM_COMPILED", "0")
    assert not compiled.available()
    assert Simulator(load_scene("release")).kernel is None


def test_the_kernel_is_cached_under_the_hash_of_its_source_one_per_structure():
    """Parameter values are read at run time: a sweep over them compiles once."""
    sims = [Simulator(load_scene("damped_release").replace(damping=d, link_masses=(1.0, m)))
            for d, m in ((0.123, 1.0), (0.7, 2.5))]
    for sim in sims:
        sim.run(0.5)
    module = sims[0].kernel.module
    assert sims[1].kernel.module is module and sims[0].state != sims[1].state
    source, _ = compiled.module_source(sims[1].dynamics, sims[1]._step)
    path = Path(module.__file__)
    assert path.name == f"arm_sim_kernel_{hashlib.sha256(source.encode()).hexdigest()[:20]}.py"
    assert path.read_text() == source and math.isfinite(sims[1].state[0])


def test_a_servo_scene_takes_pythons_path_on_every_interface():
    """An effort joint reads no set-point list; were its scene compiled, a node switching
    servo.interface live would stall 2 to 9 s in a compile (measured)."""
    for interface in ("position", "velocity", "effort"):
        scene = load_scene("servo_hold").replace(**{"servo.interface": [interface] * 2})
        assert Simulator(scene).path == "python", interface


def test_every_preset_without_a_servo_takes_the_compiled_path():
    """Clamps' MIN and MAX are functions, not constants: their scenes compile too."""
    for name in preset_names():
        scene = load_scene(name)
        expected = "python" if scene.servo is not None else "compiled (numba)"
        assert Simulator(scene).path == expected, name


@pytest.mark.parametrize("name", ["release", "motor_windings_hold", "stick_slip", "geared_arm",
                                  "limit_impact"])
def test_an_off_run_is_python_s_bit_for_bit_and_smooth_steps_stay_compiled(name, monkeypatch):
    """estimate off: the compiled loops with no check ever due and no shadow (issue 35);
    a smooth scene's run takes no step in Python."""
    scene = load_scene(name).replace(estimate="off", tolerance=0.0)
    python, fast = python_and_compiled(scene, monkeypatch)
    taken, step = [], fast.step_in_python
    monkeypatch.setattr(fast, "step_in_python", lambda: taken.append(fast.steps) or step())
    for sim in (python, fast):
        sim.set_command(2.0, -1.0)
    for duration in (0.37, 1.0):
        assert python.run(duration) == fast.run(duration)
        assert (python.state, python.steps, python._sound, python.energy_in_play) == (
            fast.state, fast.steps, fast._sound, fast.energy_in_play)
        assert python.switch_events == fast.switch_events
        assert python.substeps_taken == fast.substeps_taken
    assert math.isnan(fast.accumulated_error) and math.isnan(fast.error_estimate)
    if fast.switching is None:
        assert taken == []
    else:     # only the steps in which something could switch
        assert len(taken) < fast.steps / 4
