"""Stopping long work cleanly: SIGINT, SIGTERM and SIGHUP (Ctrl-C, `timeout`, systemd, a
closed terminal) all ask the work to stop, so every output ends at the same step and is
closed; a second signal stops at once (KeyboardInterrupt).

The work looks at `requested` between steps. A single step may take long (an engaged
compliant limit with huge damping: tens of thousands of sub-steps), so while the runner
has marked one as under way (`within_step`, whole_steps.py) the first signal also raises
StepInterrupted from inside it: Python runs the handler between two bytecodes, within a
sub-step. The runner then puts the simulator back at its last whole step.
"""
from __future__ import annotations

import signal
import threading

SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP")
                if hasattr(signal, name))


class StepInterrupted(BaseException):
    """A stop asked for while a step was under way: the step is not taken. A BaseException,
    as KeyboardInterrupt is, so that no `except Exception` inside the physics takes it for
    a fault of the step."""


class StopOnSignals:
    def __init__(self):
        self.requested = None          # the name of the signal that asked, once one has
        self.within_step = False       # a step under way that a stop may abandon
        self._previous = {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for number in SIGNALS:
                self._previous[number] = signal.signal(number, self._handle)
        return self

    def _handle(self, number, frame) -> None:
        if self.requested is not None:
            raise KeyboardInterrupt
        self.requested = signal.Signals(number).name
        if self.within_step:
            self.within_step = False
            raise StepInterrupted(self.requested)

    def __exit__(self, *exc) -> None:
        for number, handler in self._previous.items():
            signal.signal(number, handler)
        self._previous.clear()
