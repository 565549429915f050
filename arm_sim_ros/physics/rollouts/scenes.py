"""run_scenes: many scenes, each run for a duration, to their Outcomes."""
from __future__ import annotations

from collections.abc import Sequence

from .alone import run_alone
from .outcomes import Outcome


def run_scenes(scenes: Sequence, duration: float, *, observe=None,
               threads: int = 1) -> list[Outcome]:
    """Each scene run for `duration` (whole steps, as Simulator.run takes them), to its
    Outcome, in the order given; every number each scene's own Simulator.run gives.

    observe(indices, t, q, qd, tau), if given, is called with the trajectories chunk by
    chunk: `indices` the positions in `scenes` of the rows that follow, t (K,) the times,
    q, qd and tau (n, K, 2) (tau: the torque the joints receive, Simulator.joint_torque).
    A group of rows keeps its indices from chunk to chunk, its chunks come in time order,
    the first beginning at t = 0, and groups do not overlap; the chunks do not depend on
    `threads`. A scene that diverges, faults or cannot be built is an Outcome with its
    reason, never an exception."""
    return [run_alone(scene, duration, i, observe) for i, scene in enumerate(scenes)]
