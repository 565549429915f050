"""The node's Rerun recorder, if it has one: steps handed over in batches, everything else
in order after them, and a recorder that fails dropped with one error line (telemetry must
never stop the simulation).

Every `books_every`-th step (the recorder's) goes with its error books (readouts.error_books:
the simulator's error_estimate, accumulated_error and substeps_taken after it), so the
recording shows how far the steps may be off and what they cost. The node's story goes
with the steps, one row per tick (recorders with `node_ticks`): the commands refused during
the tick, whether it came late, the real-time factor and its sub-steps (those of its
steps): a tuple per tick here, the numbers worked out in the recorder's sender thread
(recording/rrd/story.py). The recorder learns the stamp origin (`for_node`) so that its
ros_time timeline is the JointState stamps.
"""
from __future__ import annotations

import time

from ..physics.simulator import recorded_row
from ..recording.readouts import error_books

# Steps collected before the recorder gets them in one call: 0.1 s behind at the default one
# step a tick; collecting 50 measured slower than 10 (the kept states fall out of cache).
RECORD_EVERY = 10


def make_recorder(config, log, stream=None):
    """The recorder the node's rerun_* parameters ask for, or None; on `stream` if given."""
    if not config.telemetry_enabled:
        return None
    v = config.values
    try:
        from ..recording.rrd.telemetry import make_recorder as make  # heavy (rerun); only when asked
        return make(config.scene, path=v["rerun_path"] or None, spawn=v["rerun_spawn"],
                    connect=v["rerun_connect"] or None, warn=log.warning, stream=stream)
    except Exception as error:  # telemetry must never stop the simulation
        log.error(f"Rerun telemetry is off: {error}")
        return None


class RecorderLink:
    def __init__(self, log, recorder, sim, stamp_origin_ns: int | None = None):
        self.log, self.recorder, self.sim = log, recorder, sim
        self.stream = getattr(recorder, "stream", None)   # the node's one Rerun stream
        self._unrecorded = []             # states of steps the recorder has not seen yet
        self._books = []                  # error books of some of them (step_batch's `books`)
        self._books_every = getattr(recorder, "books_every", 0)   # 0: none
        self._ticks = []                  # (sim.steps, story values) of those steps' ticks
        self._refused = 0                 # commands refused since the last tick
        self.stamp_origin_ns = stamp_origin_ns
        self._story = hasattr(recorder, "node_ticks")
        if hasattr(recorder, "for_node"):
            self.call("for_node", stamp_origin_ns)
        self.call("start", sim)

    def reopen(self, config) -> "RecorderLink":
        """rerun_* changed: this recording finished (its file closed, complete) and the
        link to the next, on the same Rerun stream: rerun frees no stream before the process
        exits (rerun#2116), so a new one per change would leak its threads and memory."""
        stream = self.stream
        self.finish()
        link = RecorderLink(self.log, make_recorder(config, self.log, stream), self.sim,
                            stamp_origin_ns=self.stamp_origin_ns)
        link.stream = link.stream or stream
        return link

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

    def refused(self, reason: str) -> None:
        """A refused command: a warning in the events, counted in the tick's story."""
        self._refused += 1
        self.event(f"refused command: {reason}", "warn")

    def step(self, steps: int, wall_now: float | None = None,
             late_ticks: int | None = None) -> None:
        """One tick's `steps` physics steps, each seen by the recorder: their states (and
        every books_every-th step's error books) collected and handed over in one
        step_batch(sim, states, books) call per RECORD_EVERY steps
        when it has one (a Python call per step, or per tick at one step a tick, costs more
        than logging's 10 % budget), else step(sim) after every step. `wall_now` (the core's
        clock at the tick; default time.monotonic()) and `late_ticks` (the core's count;
        default: not recorded) make the tick's story."""
        if self._story and self.recorder is not None:
            self._tell(steps, time.monotonic() if wall_now is None else wall_now, late_ticks)
        sim, recorder = self.sim, self.recorder
        advance = sim.step
        if recorder is None:
            for _ in range(steps):
                advance()
        elif hasattr(recorder, "step_batch"):
            keep, book, every = self._unrecorded.append, self._books.extend, self._books_every
            for _ in range(steps):
                advance()
                keep(recorded_row(sim))
                if every and sim.steps % every == 0:
                    book(error_books(sim))
            if len(self._unrecorded) >= RECORD_EVERY:
                self.hand_over()
        else:
            for _ in range(steps):
                advance()
                self.call("step", sim)

    def _tell(self, steps: int, wall: float, late_ticks: int | None) -> None:
        """The tick's story, kept with its steps (which come next) as noted: story.TickStory."""
        sim = self.sim
        self._ticks.append((sim.steps + steps, (wall, late_ticks, self._refused, steps,
                                                sim.step_size)))
        self._refused = 0

    def hand_over(self) -> None:
        states, self._unrecorded = self._unrecorded, []
        books, self._books = self._books, []
        ticks, self._ticks = self._ticks, []
        if states:
            self.call("step_batch", self.sim, states, books)
        if ticks and states:
            self.call("node_ticks", self.sim, ticks)

    def idle(self) -> None:
        """Nothing is stepping (lockstep waiting for its answer): what is kept goes to the
        recorder, and out to its file when a send is due, as the steps would send it (a
        test reads the recording of a run that stopped while the node goes on)."""
        self.hand_over()
        if self.recorder is not None and hasattr(self.recorder, "flush"):
            self.call("flush", self.sim)

    def finish(self) -> bool:
        """The recording finished; True when it was written whole (a recorder that failed
        on the way, or none, is not)."""
        alive = self.recorder is not None
        self.call("finish", self.sim)
        written, self.recorder = alive and self.recorder is not None, None
        return written
