"""The node's story per tick, from what node/recorder_link.py noted on the simulation's side
(a tuple per tick, nothing computed there): the commands refused during the tick, whether
it came late and the real-time factor; its sub-steps come from its steps' own counts
(writer.py). Computed in the sender thread.
"""
from __future__ import annotations

from collections import deque
from math import nan

import numpy as np

RTF_WINDOW = 0.1      # wall seconds the real-time factor is averaged over (a late tick and the
                      # quick one after it would otherwise read 0.3 and 100)


class TickStory:
    """values(ticks) for each batch of ticks in order; keeps the window and the late count
    from one batch to the next."""

    def __init__(self):
        self._clock = deque()     # (wall, simulated s) of the ticks in the window
        self._simulated = 0.0     # simulated seconds the ticks took, in all
        self._late = None         # the core's late-tick count at the last tick

    def values(self, ticks, substeps) -> np.ndarray:
        """(n, 4) refused, late (0/1; nan when the core gives no count), real-time factor
        (simulated s / wall s over the last RTF_WINDOW of wall time; nan at the first tick)
        and sub-steps (`substeps`, one per tick), of ticks noted as (wall, late_ticks,
        refused, steps, h)."""
        clock, rows = self._clock, []
        for (wall, late_ticks, refused, steps, h), taken in zip(ticks, substeps):
            self._simulated += steps * h
            clock.append((wall, self._simulated))
            while len(clock) > 2 and wall - clock[1][0] >= RTF_WINDOW:
                clock.popleft()
            first, before = clock[0]
            rtf = (self._simulated - before) / (wall - first) if wall > first else nan
            late = nan if late_ticks is None else late_ticks - (self._late or 0)
            self._late = late_ticks
            rows.append((refused, late, rtf, taken))
        return np.array(rows, dtype=float).reshape(-1, 4)
