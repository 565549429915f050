"""Gaussian draws that depend only on (seed, stream, joint, sample index): counter-based.

Draw k of a joint's stream is element k mod BLOCK of a block of standard normals that
numpy's Generator makes on a Philox bit generator keyed by SeedSequence([seed, stream,
joint, k // BLOCK]). Nothing is consumed: no order of calls (pause and step, lockstep, a
transport's timing, a live change) can move a stream, and another seed goes on at the same
index in its own stream. Blocks are independent keys of a counter-based generator, so the
draws are white across blocks as within them.
"""
from __future__ import annotations

import numpy as np

BLOCK = 1024                  # draws made at once: ~0.2 µs each (benchmarks/bench_sensors.py)
POSITION, VELOCITY = 0, 1     # the streams: a position's noise, a velocity's


class Draws:
    """Standard normal draws of one seed, by (stream, joint, index); the latest block of
    each (stream, joint) kept."""

    def __init__(self, seed: int):
        self.seed = int(seed)
        self._blocks = {}

    def normal(self, stream: int, joint: int, index: int) -> float:
        block, at = divmod(index, BLOCK)
        kept = self._blocks.get((stream, joint))
        if kept is None or kept[0] != block:
            kept = self._blocks[(stream, joint)] = (block, normals(self.seed, stream, joint,
                                                                   block).tolist())
        return kept[1][at]


def normals(seed: int, stream: int, joint: int, block: int) -> np.ndarray:
    """The BLOCK standard normals of one block."""
    key = np.random.SeedSequence([int(seed), stream, joint, block])
    return np.random.Generator(np.random.Philox(key)).standard_normal(BLOCK)
