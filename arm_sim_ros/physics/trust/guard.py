"""Divergence and books that do not close. A state can be finite and still be nonsense: an
unstable step (far too large for the motion) grows energy from nothing long before it
overflows, and the energy books see it at once.

Every state is checked as it is made (the energy balance residual costs one energy
evaluation, which a run computes anyway for its largest residual): a diverged state never
becomes the simulator's state, and so never reaches an output, whether or not a NaN comes
after it, and a run's outcome does not depend on how it is split into calls.

The scale is the energy in play: the most energy the run has had in motion (E above the
lowest energy the effects can store, so where V = 0 does not matter), at the start and
every CHECK_EVERY steps of sound states (a state diverging slowly cannot raise its own
bar), or as the books expect it now (E(0) plus the inputs). Losses do not widen it: a loss
the books miss is what the check is for. A residual beyond all of it has diverged (the
last sound state, the step before, is held); one beyond BOOKS_FRACTION of it means the
books do not close (said once, the run goes on and ends in failure).
"""
from __future__ import annotations

from math import isfinite

from .. import model
from ..model import MAX_ANGLE, ParameterError

CHECK_EVERY = 64          # steps between raises of the energy in play (a state's own peak)
BOOKS_FRACTION = 0.25     # a method that resolves the motion keeps its energy error within
                          # this (release over 10 s: rk4 at 50 ms 3.4 %, semi-implicit Euler
                          # at 2 ms 5.5 %; at 10 ms it reaches 27 %, said)
FLOOR = 1e-9              # J: rounding of an arm at rest


def lowest_energy(sim) -> float:
    """The least energy the effects can store: motion starts from there."""
    return sum(effect.lowest_stored_energy(sim.arm) for effect in sim.dynamics.active)


def in_play(sim, state) -> float:
    """Energy set in motion, or that can be: E above the lowest the effects store."""
    return sim.energy(state) - sim.lowest_energy


def scale(sim, state) -> float:
    """The energy in play: the most seen in sound states, or the books' E(0) + inputs."""
    inputs, _ = sim.books(state)
    expected = sim.initial_energy - sim.lowest_energy + abs(inputs)
    return FLOOR + max(sim.energy_in_play, expected)


def divergence(sim, state, residual: float) -> str | None:
    """Why `state` (its energy balance `residual`) has diverged, or None if it is sound."""
    largest = scale(sim, state)
    if not abs(residual) <= largest:                   # NaN too
        return (f"diverged: the energy balance is off by {residual:.3g} J, more than the "
                f"{largest:.3g} J in play (the step is too large for this motion: reduce "
                "step_size)")
    if not max(abs(state[0]), abs(state[1])) <= MAX_ANGLE:
        return f"diverged: an angle passed {MAX_ANGLE:g} rad (reduce step_size)"
    return None


def books_off(sim, state, residual: float) -> str | None:
    """Why the books of a sound `state` do not close, or None if they do."""
    largest = scale(sim, state)
    if abs(residual) <= BOOKS_FRACTION * largest:
        return None
    return (f"the energy books do not close: the balance is off by {residual:.3g} J, "
            f"{abs(residual) / largest:.0%} of the {largest:.3g} J in play (an effect beyond "
            "what this step size resolves: reduce step_size or set a tolerance)")


def audit(sim, residual: float) -> bool:
    """After a sound state: every CHECK_EVERY steps the energy in play keeps its peak, and
    books that do not close become the run's fault (True the first time)."""
    if sim.steps % CHECK_EVERY == 0:
        sim.energy_in_play = max(sim.energy_in_play, in_play(sim, sim.state))
    off = sim.books_fault is None and books_off(sim, sim.state, residual)
    if off:
        sim.books_fault = sim.fault = f"at t = {sim.time:.6g} s {off}"
    return bool(off)


def check_start(sim) -> None:
    """ParameterError (one line, naming what to change) where the scene starts beyond double
    precision: its energy (initial velocities of 1e300 rad/s, springs stretched 1e308 rad),
    the least energy its effects can store (gravity of 1e308), the torque the drive asks
    (a controller model's gravity of 1e308) or the sensors' first reading. Every later
    state is checked as it is made; a start that is not finite would hold at once, its
    outputs not finite: refused here, the same at the node's start, live and offline."""
    state = sim.state
    if not isfinite(model.kinetic_energy(sim.arm, state[0:2], state[2:4])):
        raise ParameterError(f"initial_velocities = {list(state[2:4])} give this arm a "
                             "kinetic energy beyond double precision; use speeds at a robot's "
                             "scale")
    if not isfinite(in_play(sim, state)):       # E - its lowest: each part, and their sum
        beyond = [effect.name for effect in sim.dynamics.active
                  if not isfinite(stored_range(sim, effect, state))]
        raise ParameterError(f"{'+'.join(beyond) or 'the effects'}: the energy stored (at the "
                             "initial state, or at its lowest) is beyond double precision with "
                             "these values; use values at a robot's scale")
    torque = sim.joint_torque()
    if not all(isfinite(v) for v in torque):
        raise ParameterError(f"the torque at the initial state is {list(torque)} N m, beyond "
                             "double precision with these values (gravity, masses, gains); use "
                             "values at a robot's scale")
    if sim.scene.sensors is not None and not all(isfinite(v) for v in sim.readings):
        raise ParameterError(f"the sensors' first reading {list(sim.readings)} is beyond double "
                             "precision; use sensors at a robot's scale")


def stored_range(sim, effect, state) -> float:
    """What `effect` stores at `state` above the least it can (inf past the doubles)."""
    start = sim.extra.index(effect.state[0]) if effect.state else 0
    extra = state[4 + start:4 + start + len(effect.state)]
    try:
        return effect.stored_energy(sim.arm, state[0:2], extra) - effect.lowest_stored_energy(
            sim.arm)
    except (OverflowError, ValueError):
        return float("inf")
