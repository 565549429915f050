"""How the node stops on SIGINT and SIGTERM, cleanly at any moment: the handler (Stop) and
the line of a node stopped while it started. Imports nothing heavy: the console script
(entry.py) installs it before the node's modules are imported."""
from __future__ import annotations

import signal


class Stop:
    """SIGINT and SIGTERM: KeyboardInterrupt where Python is, and remembered, because one
    raised inside a C library's callback into Python is printed and dropped there (llvmlite's,
    while numba compiles a scene's code at the first tick: the node ran on). The dds loop
    reads `requested` every pass. While `starting`, the first signal only is remembered: the
    node stops once it has started."""

    requested = False
    starting = False
    name = ""                 # the signal's, e.g. SIGINT

    def __call__(self, number, frame):
        again = self.requested
        self.requested, self.name = True, signal.Signals(number).name
        if self.starting and not again:
            return
        raise KeyboardInterrupt

    def install(self) -> "Stop":
        # launch stops nodes with SIGINT, then SIGTERM: both end the loop the same clean way.
        # SIGINT too, explicitly: Python leaves it ignored when the parent started us with it
        # ignored (`nohup`, `cmd &` in a script), and then Ctrl-C could never stop the node.
        for number in (signal.SIGINT, signal.SIGTERM):
            signal.signal(number, self)
        return self


def stopped_while_starting(stop: Stop, recording: str) -> str:
    """The line of a node stopped before its first step: what was written."""
    return f"arm_sim_node: stopped by {stop.name or 'a signal'} while it started, before " \
           f"its first step; {recording}"
