"""What a run of one scene comes to (Outcome), and how a Simulator's run becomes one.

status: ok; diverged (the divergence check found energy from nothing, the last sound state
held from there: guard.py); fault (a step that would leave the finite numbers was refused,
the last finite state held; or the run raised); refused (the scene cannot be run: its
simulator cannot be built, or the duration is not a whole number of its steps). `reason` is
the simulator's own one line for the first refusal, "" when ok.
"""
from __future__ import annotations

from dataclasses import dataclass
from math import nan

import numpy as np

OBSERVE_STEPS = 1000     # steps in each chunk of a trajectory handed to `observe`


@dataclass(frozen=True)
class Outcome:
    """One scene's run: the final state, the steps and sub-steps taken, the largest
    |energy-balance residual| at any step, the global error estimate (NaN with estimate
    off), and how it ended."""

    q: np.ndarray                  # (2,) rad, final
    qd: np.ndarray                 # (2,) rad/s, final
    steps: int
    substeps: int                  # the sub-steps taken (Simulator.substeps_taken)
    max_abs_residual: float        # J
    accumulated_error: float       # rad and rad/s; NaN where the run estimates none
    status: str = "ok"             # ok, diverged, refused or fault
    reason: str = ""               # the one line that says why, "" when ok


STATUSES = ("ok", "diverged", "refused", "fault")


def refused(reason: str) -> Outcome:
    """A scene that cannot be run: nothing taken, NaN where a number would be."""
    return Outcome(np.full(2, nan), np.full(2, nan), 0, 0, nan, nan, "refused", reason)


class FirstFault:
    """A simulator's first `fault` event (its message names the step it happened at): an
    event listener."""

    def __init__(self):
        self.message = ""

    def __call__(self, event) -> None:
        if event.kind == "fault" and not self.message:
            self.message = event.message


def outcome_of(sim, largest: float, first: FirstFault, error: Exception | None = None) -> Outcome:
    """The Outcome of `sim` after a run whose largest |residual| was `largest`; `error`: what
    the run raised, if it did."""
    q, qd = np.array(sim.state[0:2], dtype=float), np.array(sim.state[2:4], dtype=float)
    status, reason = "ok", ""
    if error is not None:
        status, reason = "fault", one_line(error)
    elif sim.diverged:
        status, reason = "diverged", first.message or sim.fault or sim.diverged
    elif sim.refused_steps:
        status, reason = "fault", first.message or sim.fault
    return Outcome(q, qd, sim.steps, sim.substeps_taken, float(largest),
                   float(sim.accumulated_error), status, reason)


def one_line(error: Exception, named: bool = True) -> str:
    """The first line of what `error` says (after its type's name where `named`)."""
    text = (str(error).strip().splitlines() or [""])[0]
    if not named and text:
        return text
    return f"{type(error).__name__}: {text}" if text else type(error).__name__
