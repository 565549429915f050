"""A switching scene's Simulator.run on the compiled path: the steps in which nothing can
switch, in one compiled call per stretch in one mode (switch_kernel.run_switching); every
other step as Simulator.step takes it.

The compiled run starts only where the next step is exactly what events.Switching.advance
and the error books would take from here in the current mode: the stepper's mode belongs
to the state (not set from outside, no new command for the clamps), no compliant limit is
engaged, the books' count is the stepper's, and the shadow, where it is followed, is
stepped by a twin in the same mode. The kernel hands back the first step in which
anything could switch; Python takes it (and locates what it finds), then the compiled
run goes on.
"""
from __future__ import annotations

import numpy as np

from ..trust import accuracy
from ..trust.unestimated import Off
from ..switching.events import STEEP


class Switched:
    """The compiled runs of a switching scene's modes (runs.Steps compiles each mode's
    module, its switching run included, when the run first meets the mode)."""

    def __deepcopy__(self, memo):   # compiled machinery and scratch: shared by copies
        return self

    def __init__(self, steps, driven: bool):
        self.steps, self.driven = steps, driven
        self.X, self.E = np.zeros(4), np.zeros(8)

    def run(self, kernel, sim, left: int, largest: float):
        """(steps taken, largest |residual|, code) as runs.Kernel.books_run: code 1,
        with no step taken, where Python must take the next step."""
        books, stepper = sim.accuracy, sim.switching
        compiled = self.ready(sim, books, stepper)
        if compiled is None:
            return 0, largest, 1
        module, K = compiled
        friction, mode, off = stepper.friction, stepper.mode, isinstance(books, Off)
        edge = STEEP * (friction.stribeck_velocity or 0.0) if friction is not None else 0.0
        steep = edge > 0.0 and not off           # a sliding joint in Stribeck's dip: checked
        self.X[:] = (steep and mode[0] in ("+", "-"), steep and mode[1] in ("+", "-"), edge,
                     self.driven)
        since = getattr(books, "since", 0)
        done, largest, code = kernel.books_run(sim, books, left, largest, module.run_switching,
                                               K, (self.X, self.E, kernel.D))
        if done:
            stepper.last = sim.state             # the mode goes on from here
            if off:
                return done, largest, code
            if books.shadow.last is sim.state:
                books.twin.last = books.shadow.shadow
            if books.since != since and books.tolerance:
                books.tried = {}                 # accuracy.more: a check that met the tolerance
        return done, largest, code

    def ready(self, sim, books, stepper):
        """(the current mode's module, its K), or None where the next step is Python's."""
        if sim.diverged or sim.sampled is not None or not isinstance(
                books, (accuracy.Accuracy, Off)) or books.stepper is not stepper or \
                stepper.last is not sim.state:
            return None
        mode = stepper.mode
        if mode[2] or mode[3] or stale(stepper) or books.substeps != stepper.substeps:
            return None
        if not isinstance(books, Off) and not self.followed(sim, books, mode):
            return None
        rhs, _, _, kinds, _ = stepper.functions(mode)
        if not kinds or not getattr(rhs, "guards_source", ""):
            return None
        module, K = self.steps.module(rhs)
        return None if module is None else (module, K)


    @staticmethod
    def followed(sim, books, mode) -> bool:
        """The error books' count is the stepper's, and the shadow, where it is followed,
        steps by a twin in the same mode."""
        twin, shadow = books.twin, books.shadow
        if books.free.n != books.substeps:
            return False
        followed = shadow.local is not None and not shadow.lost and sim.state is shadow.last
        return not followed or (twin is not None and twin.mode == mode and
                                twin.last is shadow.shadow and not stale(twin))


def stale(stepper) -> bool:
    """A new command: the clamps' modes are found again at the step's start (Python's)."""
    return stepper.clamps is not None and stepper.clamps.stale()
