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
command line installs one where a person reads its stderr) and on the logger
arm_sim_ros.compile (the node's log); each compile is timed (compile_seconds), so that a
progress estimate (tools/progress.py) can leave the compile out.
"""
from __future__ import annotations

import logging
import os
import sys
import threading
import time

KERNEL_MODULES = "arm_sim_kernel_"   # build.load's module names
# CPU seconds of a scene's first compile, measured with an empty cache on a 2-core machine
# (release and damped_release 10 s: their step, residual and run kernel; stick_slip 30 s
# and geared_arm 36 s, each switching mode the run meets a module of its own): the wall
# time it takes is this times how crowded the cores are.
FIRST_COMPILE_CPU = {"smooth": 10.0, "switching": 30.0}
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


COMPILES = Compiles()


def compile_seconds() -> float:
    """Wall seconds this process has spent compiling kernels (0 with a warm cache)."""
    return COMPILES.total()


def expected_seconds(switching: bool = False) -> float:
    """About how long a first compile takes here now: its CPU time, stretched by the load."""
    try:
        crowding = os.getloadavg()[0] / (os.cpu_count() or 1)
    except OSError:
        crowding = 1.0
    return FIRST_COMPILE_CPU["switching" if switching else "smooth"] * max(1.0, crowding)


def notice(line: str) -> None:
    _log.info(line)
    for listener in listeners:
        listener(line)


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
