"""The node's Rerun recorder, if it has one: steps handed over in batches, everything else
in order after them, and a recorder that fails dropped with one error line (telemetry must
never stop the simulation).
"""
from __future__ import annotations

# Steps collected before the recorder gets them in one call: 0.1 s behind at the default one
# step a tick; collecting 50 measured slower than 10 (the kept states fall out of cache).
RECORD_EVERY = 10


def make_recorder(config, log):
    """The recorder the node's rerun_* parameters ask for, or None."""
    if not config.telemetry_enabled:
        return None
    v = config.values
    try:
        from ..recording.telemetry import make_recorder as make  # heavy (rerun); only when asked
        return make(config.scene, path=v["rerun_path"] or None, spawn=v["rerun_spawn"],
                    connect=v["rerun_connect"] or None, warn=log.warning)
    except Exception as error:  # telemetry must never stop the simulation
        log.error(f"Rerun telemetry is off: {error}")
        return None


class RecorderLink:
    def __init__(self, log, recorder, sim):
        self.log, self.recorder, self.sim = log, recorder, sim
        self._unrecorded = []             # states of steps the recorder has not seen yet
        self.call("start", sim)

    def start(self, sim) -> None:
        """A new simulator (reset or rebuilt): the old one's steps go first."""
        self.hand_over()
        self.sim = sim
        self.call("start", sim)

    def call(self, method: str, *args) -> None:
        if self.recorder is None:
            return
        if self._unrecorded and method != "step_batch":
            self.hand_over()              # the steps first, then what came after them
        try:
            getattr(self.recorder, method)(*args)
        except Exception as error:  # a failing sink is dropped, the simulation goes on
            self.log.error(f"Rerun telemetry failed in {method}() and is now off: {error}")
            self.recorder = None

    def event(self, text: str, level: str = "info") -> None:
        """A line in the recording's events, at the level the node logged it."""
        self.call("event", text, level)

    def step(self, steps: int) -> None:
        """`steps` physics steps, each seen by the recorder: their states collected and
        handed over in one step_batch(sim, states) call per RECORD_EVERY steps when it has
        one (a Python call per step, or per tick at one step a tick, costs more than
        logging's 10 % budget), else step(sim) after every step."""
        sim, recorder = self.sim, self.recorder
        advance = sim.step
        if recorder is None:
            for _ in range(steps):
                advance()
        elif hasattr(recorder, "step_batch"):
            keep = self._unrecorded.append
            for _ in range(steps):
                advance()
                keep(sim.state)
            if len(self._unrecorded) >= RECORD_EVERY:
                self.hand_over()
        else:
            for _ in range(steps):
                advance()
                self.call("step", sim)

    def hand_over(self) -> None:
        states, self._unrecorded = self._unrecorded, []
        if states:
            self.call("step_batch", self.sim, states)

    def finish(self) -> None:
        self.call("finish", self.sim)
        self.recorder = None
