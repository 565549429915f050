"""Signs of life for long work: a tqdm bar on stderr when it is a terminal, a plain line
at least every 10 s otherwise; nothing for work done within QUIET_FOR seconds. A first
compile says so whatever stderr is, and a compile that goes on says so again at least every
10 s (physics/compiled/cache.py's Pulse, on the same lines). The time left is estimated from
the work's own pace since the last compile ended: no time-left figure counts a compile, and
while one is under way none is given.
"""
from __future__ import annotations

import sys
import threading
import time

from ..physics.compiled import cache
from ..physics.compiled.cache import compile_seconds

QUIET_FOR = 2.0        # wall seconds of work before any progress is shown
PLAIN_PERIOD = 7.5     # wall seconds between plain lines: with a check every few 0.01 s
                       # (and a loaded machine's delays), a line at least every 10 s off a terminal
PACE_AFTER = 1.0       # wall seconds of work (no compile) before a time left is given


class Lines:
    """One stream's lines, from any thread, and when the last was written (so that the
    compile pulse and the progress lines keep one cadence). On a terminal with a bar, a line
    goes above the bar."""

    def __init__(self, stream=None, clock=time.monotonic):
        self._stream, self.clock = stream, clock
        self.lock, self.last, self.bar = threading.RLock(), clock(), None

    stream = property(lambda self: sys.stderr if self._stream is None else self._stream)

    def say(self, line: str) -> None:
        with self.lock:
            if self.bar is not None:
                self.bar.write(line, file=self.stream)
            else:
                print(line, file=self.stream, flush=True)
            self.last = self.clock()


STDERR = Lines()


def watch_compiles(prefix: str, lines: Lines = STDERR) -> None:
    """A command line's compile lines on `lines`: the first compile's notice, then "still
    compiling" at least every 10 s while one goes on; once per process."""
    if getattr(watch_compiles, "pulse", None) is not None:
        return
    cache.listeners.append(lambda line: lines.say(f"{prefix}: {line}"))
    watch_compiles.pulse = cache.Pulse(lambda line: lines.say(f"{prefix}: {line}"),
                                       last_line=lambda: lines.last, clock=lines.clock).start()


class Progress:
    def __init__(self, total: float, label: str, unit: str = "s", stream=None,
                 clock=time.monotonic, lines: Lines | None = None):
        self.total, self.label, self.unit = total, label, unit
        self.lines = lines or (STDERR if stream is None else Lines(stream, clock))
        self.clock = clock
        self.started = clock()
        self.done = 0.0
        self.bar = None
        self.compiled = compile_seconds()     # compiling so far
        self.pace_from = (self.started, 0.0)  # (when, done): the pace is measured from here
        self.own = None                       # the work's seconds, where its caller measures

    def update(self, done: float) -> None:
        self.done = done
        now = self.clock()
        if compile_seconds() != self.compiled:     # a compile since: its time is no pace
            self.compiled, self.pace_from = compile_seconds(), (now, done)
        if now - self.started < QUIET_FOR or self.total <= 0:
            return
        if _is_terminal(self.lines.stream):
            with self.lines.lock:
                if self.bar is None:
                    from tqdm import tqdm
                    self.bar = tqdm(total=self.total, desc=self.label, unit=self.unit,
                                    file=self.lines.stream, leave=False, dynamic_ncols=True,
                                    bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.4g}/"
                                               "{total:.4g} {unit} [{elapsed}, {postfix}]")
                    self.lines.bar = self.bar
                self.bar.n = done
                self.bar.set_postfix_str(self.left(now), refresh=True)
        elif now - max(self.lines.last, self.started) >= PLAIN_PERIOD:   # the work's own lines
            fraction = done / self.total
            self.lines.say(f"{self.label}: {done:.6g} of {self.total:.6g} {self.unit} "
                           f"({100 * fraction:.1f} %), {self.left(now)}")

    def measured(self, seconds: float) -> None:
        """The work's own wall seconds so far, as its caller measured them (work done in
        other processes, their compiling left out): the time left is paced by them."""
        self.own = seconds

    def left(self, now: float) -> str:
        """"about N left", from the pace since the last compile ended (or the caller's own
        measure of the work); or why not yet."""
        if self.own is not None:
            if self.own <= 0 or self.done <= 0:
                return "time left not known yet"
            return f"about {_duration(self.own * (self.total - self.done) / self.done)} left"
        since, done_then = self.pace_from
        if now - since < PACE_AFTER or self.done <= done_then:
            return "time left not known yet"
        seconds = (now - since) * (self.total - self.done) / (self.done - done_then)
        return f"about {_duration(seconds)} left"

    def close(self) -> None:
        if self.bar is not None:
            with self.lines.lock:
                self.bar.close()
                self.bar = self.lines.bar = None

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
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"
