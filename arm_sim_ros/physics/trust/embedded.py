"""The error books of an embedded pair (dopri5), which controls its own steps: its own local
error estimate, and the shadow's measured on the schedule by step doubling, as a fixed-step
method's is (accuracy.py).
"""
from __future__ import annotations

from dataclasses import replace

from ..stepping.integrators import compile_step
from .shadow import FIRST_EVERY, Shadow, next_every


class Embedded:
    """The same books for an embedded pair (dopri5), whose rtol and atol, not `tolerance`,
    control it. `error_estimate` is the pair's own (the sum over its accepted sub-steps:
    its 4th-order companion's error, ~10x the 5th-order solution's). The shadow's local
    error is measured on the schedule by Richardson step doubling of the sub-steps the pair
    took: each taken again as two halves by its higher-order solution, the difference at the
    step's end x 2^p / (2^p - 1). So a check costs the work of the trajectory it checks,
    whatever tolerances led there (one trajectory, one price: `arm-sim accuracy`)."""

    def __init__(self, step, tableau, states: int = 4, clock=None):
        self.step, self.states, self.clock = step, states, clock
        self.factor = 2.0 ** tableau.order / (2.0 ** tableau.order - 1.0)
        # the pair's higher-order solution alone, without error control
        self.fixed = compile_step(replace(tableau, name=f"{tableau.name}_fixed", embedded_b=None,
                                          embedded_order=0), step.channels, extra=states - 4)
        self.substeps = 1
        self.reset()

    def reset(self) -> None:
        self.error_estimate = 0.0
        self.shadow = Shadow(self.states)
        self.due, self.every = 0, FIRST_EVERY

    def carry(self, previous, steps: int) -> None:
        """Go on from the books `previous` after `steps` steps: their global error."""
        self.shadow.carry(previous.shadow)
        self.due = steps

    def accumulated(self) -> float:
        return self.shadow.largest

    def taken(self, steps: int) -> int:
        return 0

    def plain(self, f, y, h):
        y1 = self.step(f, y, h)
        self.error_estimate = self.step.last_error
        self.shadow.follow(self.step, f, y, y1, h)
        return y1

    def check(self, f, y, h):
        y1 = self.step(f, y, h)
        self.error_estimate = self.step.last_error
        half, fixed = y, self.fixed
        for size in self.step.last_sizes:
            half = fixed(f, fixed(f, half, 0.5 * size), 0.5 * size)
        measured = [(a - b) * self.factor for a, b in zip(y1, half[:self.states])]
        predicted, self.shadow.local = self.shadow.local, measured
        self.shadow.follow(self.step, f, y, y1, h)
        self.every = next_every(self.every, predicted, measured)
        self.due = (self.clock() if self.clock else 0) + self.every
        return y1
