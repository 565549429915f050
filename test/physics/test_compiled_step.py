"""Issue 35: Simulator.step, the node's path, takes its step, its error books, the shadow,
the checks and their schedule in one compiled call (compiled/runs.py: Kernel.step), handing
back to Python only where Python must speak; the books stay in the kernel's arrays between
calls and are written back whenever Python reads them. The states and books are the
pure-Python path's, bit for bit. Skipped without numba, and in .ci/run's pure-Python pass
(ARM_SIM_COMPILED=0): test_compiled's import skips it then, as it skips itself."""
import pytest
from hypothesis import given, strategies as st

from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator, abs_residual

from physics.test_compiled import (books as error_books, drawn_start, fuzz,
                                   python_and_compiled)

SCENES = {
    "release": load_scene("release"),
    "release_tight": load_scene("release").replace(tolerance=1e-8),
    "damped_release_1ms": load_scene("damped_release").replace(step_size=0.001),
    "windings_exponential": load_scene("motor_windings_hold").replace(
        integrator="exponential_rk4", initial_velocities=(1.0, -2.0)),
    "stick_slip": load_scene("stick_slip"),
    "geared_arm": load_scene("geared_arm"),
    "limit_impact": load_scene("limit_impact"),
    "release_off": load_scene("release").replace(estimate="off", tolerance=0.0),
    "stick_slip_off": load_scene("stick_slip").replace(estimate="off", tolerance=0.0),
}


def outcome(sim) -> str:
    """What a run leaves: state, books (settled: read from Python's objects), refusals; as
    text, so that a NaN (a divergent run's lost estimate) equals a NaN, -0.0 is not 0.0, and
    floats are compared to the last bit (repr round-trips)."""
    counts = sorted(sim.switch_events.items())
    if sim.accuracy.shadow is None:          # estimate off: no books to compare
        return repr((sim.state, sim.steps, sim._sound, sim.energy_in_play, sim.fault,
                     sim.refused_steps, counts, sim.substeps_taken,
                     [(e.t, e.message) for e in sim.events]))
    return repr((*error_books(sim), sim.refused_steps, counts, sim.substeps_taken))


@pytest.mark.parametrize("name", SCENES)
def test_compiled_steps_leave_what_python_steps_leave_bit_for_bit(name, monkeypatch):
    """Commands changing as a node's do, the books read now and then (each read writes the
    held books back; the next step holds them again)."""
    python, fast = python_and_compiled(SCENES[name], monkeypatch)
    for k in range(400):
        if k % 23 == 0:
            for sim in (python, fast):
                sim.set_command(0.4 * (k % 5) - 0.8, 0.3)
        python.step()
        fast.step()
        if k % 97 == 0:
            assert outcome(python) == outcome(fast)
        assert python.state == fast.state
    assert outcome(python) == outcome(fast)


@pytest.mark.parametrize("name", ["release", "windings_exponential", "stick_slip",
                                  "release_off"])
def test_the_residual_a_step_hands_out_is_the_one_python_computes(name, monkeypatch):
    """abs_residual (the node books it every tick): the divergence check's |residual| of
    the state it made, compiled or not, equal to |sim.residual()| bit for bit."""
    python, fast = python_and_compiled(SCENES[name], monkeypatch)
    for k in range(150):
        for sim in (python, fast):
            if k % 40 == 0:
                sim.set_command(0.5 - 0.01 * k, 0.2)
            sim.step()
            assert abs_residual(sim) == abs(sim.residual())
        assert abs_residual(python) == abs_residual(fast)


@pytest.mark.parametrize("name", ["release", "damped_release_1ms", "release_off"])
def test_a_smooth_scene_s_steps_are_one_compiled_call_each(name, monkeypatch):
    """No step of a smooth scene is Python's but one that says something (a new highest
    sub-step count), a new command each step included (it makes the next step a check,
    inside the compiled loop)."""
    sim = Simulator(SCENES[name])
    taken, step = [], sim.step_in_python
    monkeypatch.setattr(sim, "step_in_python", lambda: taken.append(sim.steps) or step())
    for k in range(500):
        sim.set_command(0.01 * k, -0.02 * k)
        sim.step()
    said = {round(event.t / sim.step_size) for event in sim.events}
    assert set(taken) <= said and len(taken) <= 3 and sim.steps == 500
    assert sim.kernel.held is not None


def test_a_switching_scene_s_steps_are_python_s_only_where_something_could_switch(
        monkeypatch):
    python, fast = python_and_compiled(SCENES["stick_slip"], monkeypatch)
    taken, step = [], fast.step_in_python
    monkeypatch.setattr(fast, "step_in_python", lambda: taken.append(fast.steps) or step())
    for _ in range(300):
        python.step()
        fast.step()
    assert outcome(python) == outcome(fast)
    assert sum(python.switch_events.values()) > 0 and 0 < len(taken) < 60


def test_held_books_survive_a_payload_grasp_a_reset_and_a_run(monkeypatch):
    python, fast = python_and_compiled(SCENES["release"], monkeypatch)
    for sim in (python, fast):
        for _ in range(30):
            sim.step()
        sim.set_payload(0.8)
        for _ in range(30):
            sim.step()
        sim.run(0.3)
        for _ in range(7):
            sim.step()
    assert outcome(python) == outcome(fast)
    for sim in (python, fast):
        sim.reset()
        for _ in range(40):
            sim.step()
    assert outcome(python) == outcome(fast)


def test_a_state_set_from_outside_is_stepped_from_as_python_steps_from_it(monkeypatch):
    python, fast = python_and_compiled(SCENES["release"], monkeypatch)
    for sim in (python, fast):
        for _ in range(20):
            sim.step()
        sim.state = (0.3, -0.2, 1.0, 0.5)
        for _ in range(20):
            sim.step()
    assert outcome(python) == outcome(fast)


DIVERGING = [load_scene("payload_release").replace(payload={"mass": mass}, tolerance=0.0)
             for mass in (1e4, 3e5, 1e6, 3e6)]


@pytest.mark.parametrize("scene", DIVERGING, ids=["1e4", "3e5", "1e6", "3e6"])
def test_a_divergent_run_steps_as_it_runs_on_either_path(scene, monkeypatch):
    """issue 39's hunt: the same state, fault and refusals by steps, by one run, by runs of
    a step each, compiled or not."""
    outcomes = []
    for compiled in ("0", "1"):
        monkeypatch.setenv("ARM_SIM_COMPILED", compiled)
        for how in ("steps", "run", "runs"):
            sim = Simulator(scene)
            if how == "steps":
                for _ in range(50):
                    sim.step()
            elif how == "run":
                sim.run(0.5)
            else:
                for _ in range(50):
                    sim.run(0.01)
            outcomes.append((sim.state, sim.fault, sim.refused_steps, sim.diverged))
    assert all(o == outcomes[0] for o in outcomes) and outcomes[0][1] is not None


@st.composite
def stepped_runs(draw):
    """A preset from a random state, tolerance and estimate, divergent ones among them (a
    payload far too heavy, a step far too long), stepped under changing commands."""
    name = draw(st.sampled_from(["release", "damped_release", "springs_oscillation",
                                 "payload_release", "stick_slip", "geared_arm"]))
    scene = load_scene(name)
    scene = drawn_start(draw, scene, [0.0, 1e-7, 5e-5], "command_gravity_compensation"
                        if scene.policy == "zero" else scene.policy)
    scene = scene.replace(estimate="off" if scene.tolerance == 0.0 and draw(st.booleans())
                          else "global")
    if draw(st.booleans()):                 # divergent: the check must find it on both paths
        scene = scene.replace(payload={"mass": draw(st.sampled_from([1e4, 1e6]))},
                              step_size=scene.step_size * draw(st.sampled_from([1, 5])),
                              max_substeps=64.0)   # the tolerance's count capped: quick
    commands = [tuple(draw(st.floats(-10.0, 10.0)) for _ in (0, 1)) for _ in range(4)]
    return scene, commands


@pytest.mark.hunt          # 12 examples ~35 s (divergent switching scenes in Python)
@fuzz(12)
@given(case=stepped_runs())
def test_random_stepped_runs_leave_what_python_leaves(case, monkeypatch):
    scene, commands = case
    python, fast = python_and_compiled(scene, monkeypatch)
    for command in commands:
        for sim in (python, fast):
            sim.set_command(*command)
            for _ in range(40):
                sim.step()
        assert outcome(python) == outcome(fast)
