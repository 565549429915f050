"""How the accuracy study prices its runs: the CPU time of one whole run as a user makes it
(prepared untimed, the garbage collector off), the fastest of many calls. The runs of a scene
are called in turn, one call each, over and over (interleaved call by call, in rounds), so
that whatever the machine does meanwhile falls on every run alike and two runs of the same
work are priced alike.

Call by call, not each run back to back for its share of a round: on a shared machine a
core's speed comes and goes in spells (another process on its sibling), and a run taken whole
within a slow spell never saw a fast one. On damped_release's one trajectory in seven series
of 15 runs (test_study), at a load of 5 to 6 on 2 cores, back to back priced it at 93-177 µs
per simulated second (1.89x) and 94-142 (1.50x); call by call, in the same process between
them, 93-96 (1.04x) and 95-97 (1.02x).
The fastest call, not the median: the median moves with the load (103-121, then 182-190 µs/s
in the next run) where the fastest stays (93-115).
"""
from __future__ import annotations

import gc
import time
from dataclasses import dataclass, field
from typing import Callable

ROUND_CPU_S = 0.01      # per run and round: short runs are taken again until this much


@dataclass
class Priced:
    """A run whose numbers are measured (`run`, a runs.Run) and whose price is being taken:
    `prepare()` (untimed: back to the initial state) then `go()` (timed: the whole run)."""

    run: object
    go: Callable[[], object]
    prepare: Callable[[], object] = lambda: None
    calls: list = field(default_factory=list)     # CPU seconds of each go() so far

    def once(self) -> float:
        """CPU seconds of one go(), the garbage collector off meanwhile (as timeit does: its
        passes cost what the study's other runs hold, not what this one does)."""
        self.prepare()
        collecting = gc.isenabled()
        gc.disable()
        try:
            start = time.process_time()
            self.go()
            return time.process_time() - start
        finally:
            if collecting:
                gc.enable()


def price(priced: list[Priced], rounds: int, duration: float, tell=None) -> None:
    """Each run's CPU seconds per simulated second, the fastest of its calls. In each of
    `rounds` rounds every run is called in turn, one call each, again and again until it has
    spent ROUND_CPU_S in the round (a long run: once); `tell(done, total)` as runs finish
    their round."""
    for r in range(rounds):
        spent, left = [0.0] * len(priced), list(range(len(priced)))
        while left:
            for i in left:
                priced[i].calls.append(priced[i].once())
                spent[i] += priced[i].calls[-1]
            left = [i for i in left if spent[i] < ROUND_CPU_S]
            if tell:
                tell(r * len(priced) + len(priced) - len(left), rounds * len(priced))
    for p in priced:
        p.run.cpu_s_per_sim_s = min(p.calls) / duration if duration > 0 else 0.0
