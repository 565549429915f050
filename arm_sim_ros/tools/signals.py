"""Stopping long work cleanly: SIGINT, SIGTERM and SIGHUP (Ctrl-C, `timeout`, systemd, a
closed terminal) all ask the work to stop at its next check, so every output ends at the
same step and is closed; a second signal stops at once (KeyboardInterrupt).
"""
from __future__ import annotations

import signal
import threading

SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP")
                if hasattr(signal, name))


class StopOnSignals:
    def __init__(self):
        self.requested = None          # the name of the signal that asked, once one has
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

    def __exit__(self, *exc) -> None:
        for number, handler in self._previous.items():
            signal.signal(number, handler)
        self._previous.clear()
