"""Effort and voltage clamps switched at located events (physics/switching/clamps.py, events.py).

A clamp whose request depends on the state (gravity compensation) is a mode per joint:
passing, holding +limit, holding −limit. Its switch is located inside the step like a
friction switch, so RK4 keeps order 4 across it; with MIN/MAX inside the RK stages (what
Batch still does) or switching at sub-step ends (`locate = False`) the kink costs the order.

The reference is test_effects.FirstPrinciples (the arm from the issue's equations, no code
shared with arm_sim_ros.physics): DOP853 at rtol = atol = 1e-12, every clamp a mode whose
switch scipy's solve_ivp(events=...) locates; here it also records when.
"""
import numpy as np
import pytest

from arm_sim_ros.physics.stepping.exponential import step_for
from arm_sim_ros.physics.stepping.integrators import INTEGRATORS
from arm_sim_ros.physics.scene import Scene, load_scene
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.physics.stepping.stability import substepping
from physics.test_effects import EFFECT_CASES, FirstPrinciples, MOVING, WINDINGS

STEPS = (0.01, 0.005, 0.0025, 0.00125)
# Switching late (or clamping in the stages) the error depends on where the grid falls
# against each switch: the order shows over a wider range.
UNLOCATED_STEPS = tuple(0.01 / 2 ** n for n in range(7))
CASES = {   # scene, end time: an effort-limited hold that saturates and releases both
    # joints (6 switches), and windings whose driver saturates (3 switches)
    "effort_limited_hold": (load_scene("effort_limited_hold").replace(effort_limits=(12.0, 4.0)),
                            1.5),
    "saturating_windings": (EFFECT_CASES["motors_windings_saturating"], 1.0),
}
KINDS = {("effort", 0): "effort_release", ("effort", 1): "effort_saturation",
         ("effort", -1): "effort_saturation", ("volts", 0): "voltage_release",
         ("volts", 1): "voltage_saturation", ("volts", -1): "voltage_saturation"}


class Timed(FirstPrinciples):
    """FirstPrinciples whose solve also records (t, switch_events kind, joint) per switch."""

    def solve(self, t_end):
        self.times = []
        return super().solve(t_end)

    def switched(self, t, clamp_and_joint, mode):
        clamp, joint = clamp_and_joint
        self.times.append((t, KINDS[clamp, mode], joint))


def timed(sim):
    """The simulator's switches as (t, kind, joint), recorded as they are counted."""
    times, count = [], sim.switching.count

    def record(kind, joint, at):
        times.append((sim.switching.clock() + at, kind, joint))
        count(kind, joint, at)
    sim.switching.count = record
    return times


def mode_free(sim, steps):
    """The state after `steps` steps of the mode-free right-hand side: MIN/MAX clamps in
    every RK stage (the simulator before clamps were modes; Batch today), by the scene's
    method (rk4, or exponential_rk4 for geared_arm's windings)."""
    method = INTEGRATORS[sim.scene.method]
    advance = substepping(step_for(method, len(sim.channels), sim.dynamics.decay), sim.substeps)
    y = sim.state
    for _ in range(steps):
        y = advance(sim.dynamics.function, y, sim.step_size)
    return y


def errors(scene, T, steps, how):
    exact = Timed(scene).solve(T)
    out = []
    for h in steps:
        # fixed h: the order of the step itself, no tolerance splitting it (accuracy.py)
        sim = Simulator(scene.replace(step_size=h, tolerance=0.0))
        n = 4 + len(sim.extra)
        if how == "stages":
            state = mode_free(sim, scene.steps_for(T, h))
        else:
            sim.switching.locate = how == "located"
            sim.run(T)
            state = sim.state
        out.append(float(np.max(np.abs(np.array(state[:n]) - exact[:n]))))
    return out


def order(steps, errs):
    return float(np.polyfit(np.log(steps), np.log(errs), 1)[0])


# --- Which clamps switch ----------------------------------------------------------------

def test_a_state_dependent_request_makes_its_clamps_modes_a_constant_one_stays_min_max():
    sim = Simulator(load_scene("effort_limited_hold"))
    assert sim.switching is not None and sim.switching.clamps is not None
    assert sim.switching.mode is None                     # found from the first state
    sim.step()
    assert sim.switching.mode[4] == (1, 0, 0, 0)          # asks 19.62 N m of 15: saturated
    assert "MIN(MAX(" in sim.dynamics.source              # the mode-free form (Batch)
    for scene in (load_scene("shoulder_torque_no_gravity").replace(effort_limits=(0.5, 0.5)),
                  Scene(**MOVING, policy="command", effort_limits=(1.0, 1.0),
                        motors=WINDINGS | {"voltage_limit": [1.0, 1.0]})):
        sim = Simulator(scene)                          # constant within a step: no modes
        assert sim.switching is None and sim.switch_events == {}
        assert "MIN(MAX(" in sim.dynamics.source


# --- Order, switch times, books ---------------------------------------------------------

@pytest.mark.parametrize("name", sorted(CASES))
def test_rk4_keeps_order_4_across_located_clamp_switches_and_loses_it_without(name):
    scene, T = CASES[name]
    located = errors(scene, T, STEPS, "located")
    assert 3.5 <= order(STEPS, located) <= 5.0, located
    assert located[-1] < 1e-8
    late = errors(scene, T, UNLOCATED_STEPS, "late")
    assert 0.8 <= order(UNLOCATED_STEPS, late) <= 2.6, late
    stages = errors(scene, T, UNLOCATED_STEPS, "stages")
    assert order(UNLOCATED_STEPS, stages) <= 2.6, stages
    assert late[3] > 100 * located[-1] and stages[3] > 100 * located[-1]   # at h = 0.00125


@pytest.mark.parametrize("name", sorted(CASES))
def test_each_clamp_switch_is_located_to_better_than_1e_10_s_and_counted(name):
    scene, T = CASES[name]
    ref = Timed(scene)
    ref.solve(T)
    assert len(ref.times) >= 3
    sim = Simulator(scene.replace(step_size=0.001))
    heard = []
    sim.event_listeners.append(heard.append)
    times = timed(sim)
    sim.run(T)
    assert [(kind, joint) for _, kind, joint in times] == [(k, j) for _, k, j in ref.times]
    assert max(abs(a[0] - b[0]) for a, b in zip(times, ref.times)) < 1e-10
    expected = {}
    for _, kind, _ in ref.times:
        expected[kind] = expected.get(kind, 0) + 1
    assert dict(sim.switch_events) == expected
    switches = [e for e in heard if e.kind == "switch"]
    assert len(switches) == min(5, len(ref.times)) + (len(ref.times) >= 10)
    t, kind, joint = times[0]
    assert f"{kind} of joint {joint + 1} at t = {t:.9f} s" == switches[0].message


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_books_close_across_located_clamp_switches(name):
    scene, T = CASES[name]
    sim = Simulator(scene.replace(step_size=5e-4))
    largest = sim.run(T)
    exact = Timed(scene).solve(T)
    books = sim.channel_values(sim.state)
    n = 4 + len(sim.extra)
    for k, channel in enumerate(("work", "dissipated", "electrical_input", "copper_loss")):
        if channel in books:
            assert books[channel] == pytest.approx(exact[n + k], rel=1e-9, abs=1e-9), channel
    # E(t) − E(0) − inputs + losses: RK4's own error; the windings' first current step
    # (h R/L = 0.05) dominates it there, not the clamps.
    assert largest < (1e-6 if sim.extra else 1e-10), largest


# --- A command that jumps between steps ---------------------------------------------------

def test_a_command_jump_between_steps_finds_the_clamps_again_without_counting_a_switch():
    scene = Scene(**MOVING, policy="command_gravity_compensation", effort_limits=(40.0, 20.0))
    sim = Simulator(scene)
    sim.run(0.05)
    assert sim.switching.mode[4] == (0, 0, 0, 0)
    sim.set_command(100.0, -100.0)                       # far beyond both limits
    sim.step()
    assert sim.switching.mode[4] == (1, -1, 0, 0) and sim.switch_events == {}
    assert sim.joint_torque() == (40.0, -20.0)
    sim.set_command(0.0, 0.0)
    sim.step()
    assert sim.switching.mode[4] == (0, 0, 0, 0) and sim.switch_events == {}
