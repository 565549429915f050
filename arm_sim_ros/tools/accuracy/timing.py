"""How the accuracy study prices its runs: CPU time of one whole run as a user makes it,
prepared untimed, the fastest of several, taken in rounds over every run of a scene in turn
(interleaved), so that a load that comes and goes on a shared machine falls on every run
alike and two runs of the same work are priced alike.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from math import inf
from typing import Callable

ROUND_CPU_S = 0.01      # per run and round: short runs are taken again until this much


@dataclass
class Priced:
    """A run whose numbers are measured (`run`, a runs.Run) and whose price is being taken:
    `prepare()` (untimed: back to the initial state) then `go()` (timed: the whole run)."""

    run: object
    go: Callable[[], object]
    prepare: Callable[[], object] = lambda: None
    best: float = field(default=inf)        # CPU seconds of the fastest go() so far

    def once(self) -> float:
        self.prepare()
        start = time.process_time()
        self.go()
        return time.process_time() - start

    def take(self) -> None:
        """One round: go() at least once and for at least ROUND_CPU_S, keeping the fastest."""
        spent = 0.0
        while True:
            elapsed = self.once()
            self.best, spent = min(self.best, elapsed), spent + elapsed
            if spent >= ROUND_CPU_S:
                return


def price(priced: list[Priced], rounds: int, duration: float, tell=None) -> None:
    """Each run's CPU seconds per simulated second: the fastest of `rounds` rounds over all
    of them in turn; `tell(done, total)` after each run of each round."""
    for r in range(rounds):
        for i, p in enumerate(priced):
            p.take()
            if tell:
                tell(r * len(priced) + i + 1, rounds * len(priced))
    for p in priced:
        p.run.cpu_s_per_sim_s = p.best / duration if duration > 0 else 0.0
