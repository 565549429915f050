"""The error books of an embedded pair (dopri5), which controls its own steps: its own local
error estimate, and the shadow's measured on the schedule against a tighter step.
"""
from __future__ import annotations

from .shadow import FIRST_EVERY, Shadow, next_every

TIGHTER = 1000.0          # an embedded pair's local error: against its step at tolerances / this


class Embedded:
    """The same books for an embedded pair (dopri5), whose rtol and atol, not `tolerance`,
    control it. `error_estimate` is the pair's own (the sum over its accepted sub-steps:
    its 4th-order companion's error, ~10x the 5th-order solution's). The shadow's local
    error is measured on the schedule against the same step at TIGHTER times smaller
    tolerances (an error-controlled step's error goes as its tolerance)."""

    def __init__(self, step, tight, states: int = 4, clock=None):
        self.step, self.tight, self.states, self.clock = step, tight, states, clock
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
        better = self.tight(f, y, h)
        measured = [(a - b) * TIGHTER / (TIGHTER - 1.0) for a, b in zip(y1, better[:self.states])]
        predicted, self.shadow.local = self.shadow.local, measured
        self.shadow.follow(self.step, f, y, y1, h)
        self.every = next_every(self.every, predicted, measured)
        self.due = (self.clock() if self.clock else 0) + self.every
        return y1
