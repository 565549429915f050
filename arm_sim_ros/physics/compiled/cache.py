"""What a first compile says, and how long compiling took.

The kernels are cached per machine, in ARM_SIM_CACHE (default ~/.cache/arm_sim_ros,
build.cache_dir): each scene structure's generated module (arm_sim_kernel_<hash>.py, named
by the SHA-256 of its text: build.load) and numba's machine code beside it (__pycache__: an
index and the object code of each function). Nothing in them names the checkout or the
venv, so every checkout and every venv of one machine with the same numba shares them;
a scene structure compiles once per machine. A damaged entry is set aside and compiled
again (entries.py); a cache the run cannot write gives the pure-Python path, said once
(build.available).

Loaded from that cache a kernel is ready in a fraction of a second; compiled, it takes
seconds (numba's "numba:compile" events fire only then). The first compile of a kernel
module in a process is announced in one line, before it starts, to `listeners` (the
command line installs one, whatever its stderr is: a terminal, a file or a pipe) and on
the logger arm_sim_ros.compile (the node's log). A Pulse says "still compiling" while one
goes on, so that no reader sees 10 s of silence. Each compile is timed
(compile_seconds), so that a progress estimate (tools/progress.py) can leave it out.
"""
from __future__ import annotations

import logging
import os
import sys
import threading
import time

KERNEL_MODULES = "arm_sim_kernel_"   # build.load's module names
# CPU seconds of a scene's first compile with an empty cache (release: its step, residual and
# run kernel; stick_slip: each switching mode the run meets a module of its own); the wall
# time it takes is this times how crowded the cores are. Measured: bench_speed.py's
# first_compile table, benchmarks/results/speed_first_compile.txt (test_figures holds these
# within 2x of it; a loaded machine's CPU seconds run up to twice an idle one's).
FIRST_COMPILE_CPU = {"smooth": 10.0, "switching": 30.0}
PULSE_PERIOD = 7.5                   # s without a line before a Pulse speaks; it looks every
PULSE_TICK = 0.5                     # PULSE_TICK s, and llvmlite may hold the GIL a second or
                                     # two on a loaded machine: every gap stays under 10 s
listeners: list = []                 # callables(line): who hears the notice
_log = logging.getLogger("arm_sim_ros.compile")


class Compiles:
    """numba's compile events of kernel modules: the first announced, their time summed."""

    def __init__(self):
        self.lock, self.depth, self.started, self.seconds = threading.Lock(), 0, 0.0, 0.0
        self.said = False

    def on_start(self, module: str) -> None:
        with self.lock:
            self.depth += 1
            if self.depth == 1:               # nested compiles (callees) count once
                self.started = time.perf_counter()
            say = not self.said and module.startswith(KERNEL_MODULES)
            self.said = self.said or say
        if say:
            switching = hasattr(sys.modules.get(module), "run_switching")
            notice(f"compiling this scene's kernels once for this machine, about "
                   f"{expected_seconds(switching):.0f} s (later runs load them from the cache)")

    def on_end(self) -> None:
        with self.lock:
            self.depth -= 1
            if self.depth == 0:
                self.seconds += time.perf_counter() - self.started

    def total(self) -> float:
        """Seconds spent compiling so far, a compile under way included."""
        with self.lock:
            ongoing = time.perf_counter() - self.started if self.depth else 0.0
            return self.seconds + ongoing

    def under_way(self) -> float | None:
        """While a compile is under way, the seconds this process has spent compiling (a
        scene's modes compile one after another: the sum, never back to 0); else None."""
        with self.lock:
            return self.seconds + time.perf_counter() - self.started if self.depth else None


COMPILES = Compiles()


def compile_seconds() -> float:
    """Wall seconds this process has spent compiling kernels (0 with a warm cache)."""
    return COMPILES.total()


def compiling() -> float | None:
    """Seconds spent compiling so far while a compile is under way; None when none is."""
    return COMPILES.under_way()


def expected_seconds(switching: bool = False) -> float:
    """About how long a first compile takes here now: its CPU time, stretched by the load."""
    try:
        crowding = os.getloadavg()[0] / (os.cpu_count() or 1)
    except OSError:
        crowding = 1.0
    return FIRST_COMPILE_CPU["switching" if switching else "smooth"] * max(1.0, crowding)


def notice(line: str) -> None:
    notice.said = time.monotonic()
    _log.info(line)
    for listener in listeners:
        listener(line)


notice.said = float("-inf")


class Pulse:
    """While a compile is under way, a line at least every 10 s: `say("still compiling ...")`
    once PULSE_PERIOD s have passed since the last line (`last_line()`: the stream's, default
    this pulse's own and the notice's). tick() decides, with the injected clock; start() runs
    it every PULSE_TICK s in a daemon thread."""

    def __init__(self, say, last_line=None, clock=time.monotonic, under_way=compiling):
        self.say, self.clock, self.under_way = say, clock, under_way
        self.own = clock()
        self.last_line = last_line or (lambda: max(self.own, notice.said))

    def tick(self) -> str | None:
        seconds = self.under_way()
        now = self.clock()
        if seconds is None or now - self.last_line() < PULSE_PERIOD:
            return None
        self.own = now
        line = f"still compiling this scene's kernels, {seconds:.0f} s so far"
        self.say(line)
        return line

    def start(self) -> "Pulse":
        def beat():
            while True:
                time.sleep(PULSE_TICK)
                self.tick()
        threading.Thread(target=beat, name="arm_sim_ros compile pulse", daemon=True).start()
        return self


def log_pulse() -> Pulse:
    """The node's: "still compiling" on the logger arm_sim_ros.compile, once per process."""
    if getattr(log_pulse, "pulse", None) is None:
        log_pulse.pulse = Pulse(_log.info).start()
    return log_pulse.pulse


def watch(numba_event) -> None:
    """Hear numba's compile events (numba.core.event), once per process."""
    if getattr(watch, "done", False):
        return
    watch.done = True

    class Listener(numba_event.Listener):
        def on_start(self, event):
            dispatcher = (event.data or {}).get("dispatcher")
            COMPILES.on_start(getattr(getattr(dispatcher, "py_func", None), "__module__", ""))

        def on_end(self, event):
            COMPILES.on_end()

    numba_event.register("numba:compile", Listener())
