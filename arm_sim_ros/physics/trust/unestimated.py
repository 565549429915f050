"""Books that estimate nothing: steps taken as planned, their error estimates NaN.

`estimate` (a scene key) chooses what a run computes about its own error:

    global   the error books of accuracy.py: the shadow (the global error, shadow.py) beside
             every step and the local error measured on a schedule (the default)
    off      none of it (Off): the planned steps alone, no shadow and no checks; the run
             carries no error estimate and so cannot hold a tolerance (it must be 0).
             Fit rollouts and Batch run so: a trajectory compared with a measurement, or
             thousands of arms, need the steps, not their error bars.
"""
from __future__ import annotations

ESTIMATES = ("global", "off")
NO_ESTIMATE = "this run carries no error estimate"   # what the outputs of an `off` run say


class Unchecked:
    """No estimate (NaN): steps the stability plan refuses, and dopri5 on a scene that switches
    modes (`stepper`)."""

    error_estimate = float("nan")
    due = 0
    shadow = None             # no global estimate: books after these start afresh

    def __init__(self, advance, substeps: int, stepper=None):
        self.check = self.plain = advance
        self.substeps, self.stepper = substeps, stepper

    def reset(self) -> None:
        pass

    def accumulated(self) -> float:
        return self.error_estimate

    def taken(self, steps: int) -> int:
        return (steps * self.substeps if self.substeps > 1 else 0) + (
            self.stepper.extra_substeps if self.stepper is not None else 0)


class Off(Unchecked):
    """estimate: off: the stability plan's sub-steps (switched at events by `stepper`), no
    shadow, no check. A switching step is never estimated either (the stepper's `checked`
    stays None), so a switch or a contact costs only its own sub-steps."""
