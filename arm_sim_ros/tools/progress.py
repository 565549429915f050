"""Signs of life for long work: a tqdm bar on stderr when it is a terminal, a plain line
every PLAIN_PERIOD seconds otherwise; nothing for work done within QUIET_FOR seconds. The
time left is estimated from the work's own pace: seconds spent compiling kernels (a first
compile, physics/compiled/cache.py) are left out of it.
"""
from __future__ import annotations

import sys
import time

from ..physics.compiled.cache import compile_seconds

QUIET_FOR = 2.0        # wall seconds of work before any progress is shown
PLAIN_PERIOD = 10.0    # wall seconds between plain lines when stderr is not a terminal


class Progress:
    def __init__(self, total: float, label: str, unit: str = "s", stream=None,
                 clock=time.monotonic):
        self.total, self.label, self.unit = total, label, unit
        self.stream = sys.stderr if stream is None else stream
        self.clock = clock
        self.started = self.last_line = clock()
        self.done = 0.0
        self.bar = None
        self.compiled = compile_seconds()     # compiling before the work started
        self.own = None                       # the work's seconds, where its caller measures

    def update(self, done: float) -> None:
        self.done = done
        now = self.clock()
        if now - self.started < QUIET_FOR or self.total <= 0:
            return
        if _is_terminal(self.stream):
            if self.bar is None:
                from tqdm import tqdm
                self.bar = tqdm(total=self.total, desc=self.label, unit=self.unit,
                                file=self.stream, leave=False, dynamic_ncols=True,
                                bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.4g}/{total:.4g} "
                                           "{unit} [{elapsed}<{remaining}]")
            self.bar.start_t = self.bar._time() - self.working(now)   # tqdm's pace from it
            self.bar.n = done
            self.bar.refresh()
        elif now - self.last_line >= PLAIN_PERIOD:
            self.last_line = now
            fraction = done / self.total
            left = (self.working(now) * (1 - fraction) / fraction if fraction > 0
                    else float("inf"))
            print(f"{self.label}: {done:.6g} of {self.total:.6g} {self.unit} "
                  f"({100 * fraction:.1f} %), about {_duration(left)} left",
                  file=self.stream, flush=True)

    def measured(self, seconds: float) -> None:
        """The work's own wall seconds so far, as its caller measured them (work done in
        other processes, their compiling left out): the time left is paced by them."""
        self.own = seconds

    def working(self, now: float) -> float:
        """Seconds of the work itself so far: compiling left out."""
        if self.own is not None:
            return self.own
        return now - self.started - (compile_seconds() - self.compiled)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _is_terminal(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


def _duration(seconds: float) -> str:
    if seconds == float("inf"):
        return "an unknown time"
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"
