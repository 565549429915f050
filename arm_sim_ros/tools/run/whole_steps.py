"""Steps a stop request may abandon midway: the simulator is left at its last whole step.

While a step is under way the stop handler (signals.StopOnSignals) raises StepInterrupted
from inside it, wherever the step is: in a sub-step loop, or halfway through its
bookkeeping (error books, switch counts, the shadow). The simulator's state proper is
assigned only when a step completes, but that bookkeeping is not, so the simulator is put
back as it was after its last whole step: its mutable attributes are copied at a step
boundary every KEEP_PERIOD of wall time (a deep copy: 0.1-0.4 ms, under 1 % at that
period), and an interrupted run restores the latest copy and takes the whole steps after
it again, silently (what they said was heard the first time). Those took under
KEEP_PERIOD: a copy is made before any step that starts later than that after the last.
"""
from __future__ import annotations

from copy import deepcopy
from time import perf_counter

from ...physics.simulator import abs_residual, settle
from ..signals import StepInterrupted

KEEP_PERIOD = 0.05        # wall seconds between copies: bounds the steps taken again
OWN = ("event_listeners",)    # the listeners are the caller's: never copied or restored


class WholeSteps:
    """run(steps, on_step) as Simulator.run takes them, ended by `stop` (StopOnSignals) at
    the last whole step: between steps when it is asked for between them, else by
    abandoning the step under way."""

    def __init__(self, sim, stop):
        self.sim, self.stop = sim, stop
        self._kept, self._kept_at = None, 0.0

    def run(self, steps: int, on_step=None) -> float:
        """Up to `steps` steps, on_step(sim) after each (never interrupted), as Simulator.run
        takes them. Returns the largest |residual| seen."""
        sim, stop = self.sim, self.stop
        whole = sim.steps
        largest = 0.0
        self.keep()       # a copy at each run's start: never taken again across one
        try:
            for _ in range(steps):
                if stop.requested:
                    break
                if perf_counter() - self._kept_at >= KEEP_PERIOD:
                    self.keep()
                stop.within_step = True
                try:
                    sim.step()
                finally:
                    stop.within_step = False
                largest = max(largest, abs_residual(sim))
                if on_step is not None:
                    on_step(sim)
                whole = sim.steps
        except StepInterrupted:
            self.undo(whole)
        return largest

    def keep(self) -> None:
        """A copy of the simulator's mutable attributes; what a step never changes (the
        simulator itself, as the books' callbacks hold it, its dynamics, scene, arm) is
        shared, not copied."""
        sim = self.sim
        settle(sim)        # the books a compiled kernel holds, into the objects copied
        memo = {id(fixed): fixed for fixed in (sim, sim.dynamics, sim.scene, sim.arm)}
        self._kept = deepcopy({k: v for k, v in vars(sim).items() if k not in OWN}, memo)
        self._kept_at = perf_counter()

    def undo(self, whole: int) -> None:
        """Back to the last copy, then the whole steps up to `whole` again, unheard."""
        sim = self.sim
        listeners = sim.event_listeners
        vars(sim).update(self._kept)
        settle(sim, keep=False)          # a compiled kernel's books are of the later steps
        self.keep()                      # the copy again: a later undo starts from it too
        sim.event_listeners = []
        try:
            while sim.steps < whole:
                sim.step()
        finally:
            sim.event_listeners = listeners
