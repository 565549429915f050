"""run_scenes: many scenes, each run for a duration, to their Outcomes; samples of one scene
structure stepped together (batched.py), the others each alone (alone.py)."""
from __future__ import annotations

from collections.abc import Sequence

from .alone import built, run_built
from .batched import batchable, run_together, structure
from .outcomes import OBSERVE_STEPS, Outcome

GROUP = 256     # samples built at a time (in the order given), those of one structure stepped
                # together: a fixed number, so the chunks observe sees are the same on any
                # number of threads; a few MB of simulators and arrays


def run_scenes(scenes: Sequence, duration: float, *, observe=None,
               threads: int = 1) -> list[Outcome]:
    """Each scene run for `duration` (whole steps, as Simulator.run takes them), to its
    Outcome, in the order given: every number each scene's own Simulator.run gives. Samples
    of one structure (the same effects, integrator, sensor layout and steps; any values)
    are stepped together in compiled calls, on `threads` of numba's threads (at most the
    cores it has; 0: all of them); the others each through their own Simulator.run.

    observe(indices, t, q, qd, tau), if given, is called with the trajectories chunk by
    chunk: `indices` the positions in `scenes` of the rows that follow, t (K,) the times,
    q, qd and tau (n, K, 2) (tau: the torque the joints receive, Simulator.joint_torque).
    A group of rows keeps its indices from chunk to chunk, its chunks (OBSERVE_STEPS steps)
    come in time order, the first beginning at t = 0, and groups do not overlap; the chunks
    do not depend on `threads`. A sample's rows after a step that raised are NaN. A scene
    that diverges, faults or cannot be built is an Outcome with its reason, never an
    exception."""
    outcomes: list = [None] * len(scenes)
    for first in range(0, len(scenes), GROUP):
        together: dict = {}
        for index in range(first, min(first + GROUP, len(scenes))):
            run = built(index, scenes[index], duration)
            if isinstance(run, Outcome):
                outcomes[index] = run
            elif batchable(run):
                together.setdefault(structure(run), []).append(run)
            else:
                outcomes[index] = run_built(run, observe, OBSERVE_STEPS)
        for runs in together.values():
            run_together(runs, observe, OBSERVE_STEPS, threads)
            for run in runs:
                outcomes[run.index] = run.outcome()
    return outcomes
