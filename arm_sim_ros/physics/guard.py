"""Divergence: a state can be finite and still be nonsense. An unstable step (far too large
for the motion) grows energy from nothing long before it overflows; the energy books see
it at once. A state whose balance residual exceeds all the energy in play (the initial
energy, every input and every loss), or whose angles pass the scenes' limit, has diverged.
"""
from __future__ import annotations

from .scene import MAX_INITIAL_ANGLE

CHECK_EVERY = 64          # steps between checks: one energy evaluation each (~2 % of a step)


def divergence(sim, state) -> str | None:
    """Why `state` has diverged, or None if it is sound."""
    inputs, losses = sim.books(state)
    scale = 1.0 + abs(sim.initial_energy) + abs(inputs) + abs(losses)
    residual = sim.residual(state)
    if not abs(residual) <= scale:                   # NaN too
        return (f"diverged: the energy balance is off by {residual:.3g} J, more than the "
                f"{scale:.3g} J in play (the step is too large for this motion: reduce "
                "step_size)")
    if not max(abs(state[0]), abs(state[1])) <= MAX_INITIAL_ANGLE:
        return f"diverged: an angle passed {MAX_INITIAL_ANGLE:g} rad (reduce step_size)"
    return None
