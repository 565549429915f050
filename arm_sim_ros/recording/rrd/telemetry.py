"""Rerun telemetry: the explainer's readouts on simulated time, beside a drawing of the arm.

rerun is imported only in recording/: blueprint.py names the channels and lays out the
viewer, sinks.py opens the file and the viewers, properties.py stores the scene as data,
readouts.py computes a batch's values, story.py the node's per tick, arm3d.py drives the
URDF arm, columns.py encodes them and writer.py sends them on three timelines (sim_time,
ros_time = the JointState stamps, log_time = wall clock); readback.py reads a recording
back. This module holds the recorder that the node and `arm-sim run` drive.

Recording must never slow or stop the physics: step_batch() takes a tick's states in one
call (step() one step's) and appends them to one array of doubles; a batch of steps goes
to a sender thread, which computes energies, torques and drawings with numpy and sends one
send_columns per entity (rerun encodes the chunks on threads of its own). What is left on
the simulation's side is the copy of the states and the sender's time holding the GIL;
benchmarks/bench_telemetry.py measures both. The steps waiting are kept as their states
flattened into one array of doubles (8 bytes a number rather than ~40 as tuples of floats
kept alive, and nothing left to convert while holding the GIL in the sender) and runs of
consecutive steps under one held command: [first step, command (None without a command
policy), steps]. A sink that fails (unwritable file, no viewer at the address, a viewer
that dies) is one warning; the simulation runs on.

The error books (readouts.error_books, flat) go with the states of every BOOKS_EVERY-th
step (`books_every`; the callers sample them) and of each batch's last: reading them costs
~0.6 µs, 15 % of a plain step (the simulator counts the sums when asked). Under RK4 the
estimate changes only at a check (every 16 steps, 32 while it is well under the
tolerance; physics/trust/accuracy.py), so a sample every 8 steps loses little; dopri5's steps
and a switching scene's steps with a switch are estimated every step, and there a sample
is one step's estimate in 8. recorder.step(sim) records every step's.
"""
from __future__ import annotations

import logging
import queue
import threading
import time
from array import array
from itertools import chain

import numpy as np
import rerun as rr

from .arm3d import arm3d_for
from .blueprint import blueprint
from ...physics.simulator import recorded_row
from ..readouts import Snapshot, drawn, error_books, held_by, reads_alike
from .sinks import check_rrd_file, open_sinks
from .static_data import StaticData
from .writer import BatchWriter

BATCH_STEPS = 20_000             # send at least this often: bounds memory; ~0.1 ms per send_columns
CHECK_EVERY = 256                # steps between looks at the wall clock (file)...
LIVE_CHECK_EVERY = 8             # ...and for a viewer: a node may take one step per tick
FILE_PERIOD = 1.0                # wall seconds between sends to a file...
LIVE_PERIOD = 0.1                # ...and to a viewer, which a person is watching
FLUSH_TIMEOUT = 2.0              # wall seconds finish() waits for a sink before giving up on it
BOOKS_EVERY = 8                  # steps between samples of the error books (see step_batch)
QUEUED_BATCHES = 8               # batches queued before flush() waits: bounds memory
SEGMENTS = 1000                  # physics setups in one batch before it is sent: bounds memory
LEVELS = {"debug": rr.TextLogLevel.DEBUG, "info": rr.TextLogLevel.INFO,
          "warn": rr.TextLogLevel.WARN, "warning": rr.TextLogLevel.WARN,
          "error": rr.TextLogLevel.ERROR}


class RerunRecorder:
    """A recorder for cli.RUN_RECORDERS and the node: start / step or step_batch / flush /
    event / finish. start(sim) may be called again after a reset, for a new Simulator (step()
    also notices a new one) or after a live change (it carries on). Simulated time going
    back (a reset) continues the timeline, as the node's JointState stamps do."""

    def __init__(self, scene, path=None, spawn=False, connect=None, application_id="arm_sim",
                 warn=None, stream=None):
        """`stream`: a RecordingStream to record on (a node's, finished and reused for its
        next recording: rerun frees no stream before the process exits, rerun#2116)."""
        self.scene = scene
        self.path, self.spawn, self.connect = path, spawn, connect
        self.live = bool(spawn or connect)
        self._warn, self._warned = warn or logging.getLogger(__name__).warning, set()
        self.stream = stream if stream is not None else rr.RecordingStream(application_id)
        self.sinks, self.enabled = [], False   # descriptions of the sinks that opened
        self.sim = None
        self._snapshot = None     # how the steps waiting read: sim's layout when they were taken
        self._described = None    # the latest snapshot made: the recording's so far
        self._dynamics = None     # sim.dynamics then (a payload grasped rebuilds it)
        # Steps waiting to be sent, their error books (module docstring), text lines.
        self._states, self._books, self._runs, self._events = array("d"), array("d"), [], []
        self.books_every = BOOKS_EVERY
        self._waiting = self._next = 0          # steps in self._runs; the next one's number
        # Wall clock marks [(steps waiting, time.time_ns())] at each look at the clock (log_time),
        # the node's ticks [(row, as the link noted them: story.TickStory)].
        self._walls, self._ticks = [], []
        # Rows of earlier physics setups in the batch (close_segment), and their count.
        self._segments, self._segment_rows = [], 0
        self.node = False         # a node's recording: its story per tick, ros_time its stamps
        self.stamp_origin_ns = 0  # ros_time at sim_time 0 (arm-sim run: stamps are sim time)
        self._static = StaticData(self.live)
        self._check_every = LIVE_CHECK_EVERY if self.live else CHECK_EVERY
        self._check_at = self._check_every
        self._period = LIVE_PERIOD if self.live else FILE_PERIOD
        self._last_send = time.monotonic()
        self._writer = BatchWriter(self.stream)   # the sender thread's: timeline and trace
        self._layout = None       # what the first blueprint was drawn for: Snapshot.key
        self._sender = SenderThread(self._deliver)

    # -- protocol ---------------------------------------------------------------------

    def for_node(self, stamp_origin_ns: int | None) -> None:
        """Before start(): a node whose JointState stamps are stamp_origin_ns + sim_time
        (None: unknown, no ros_time timeline)."""
        self.node = True
        self.stamp_origin_ns = self._writer.stamp_origin_ns = stamp_origin_ns

    def start(self, sim) -> None:
        """Begin (or, after a reset or for a new Simulator, continue) with sim's initial row.
        The simulator already bound carrying on (its effects changed live: set_payload,
        change_scene) is only bound again: its steps go on, under the run's E(0)."""
        if self._bind(sim):
            return
        self._walls.append((self._waiting, time.time_ns()))
        self.event(start_line(sim))
        self.step(sim)

    def step(self, sim) -> None:
        """After a physics step: keep its state and its error books (see step_batch)."""
        self.step_batch(sim, (recorded_row(sim),))

    def step_batch(self, sim, states, books=()) -> None:
        """After len(states) physics steps: their states in order, the last being sim.state,
        taken under the command sim
        holds now (the node hands its steps over before a new command). The node calls this
        every 10 steps, `arm-sim run` every 1000; the states are copied, so the caller may
        reuse the list; `books`: the error books of every books_every-th step among them
        (module docstring). Nothing else happens (see flush)."""
        if sim is not self.sim or sim.dynamics is not self._dynamics:
            self._bind(sim)
        n, end = len(states), sim.steps
        if n == 0:
            return
        snap = self._snapshot     # None: it could not be made, and telemetry is off
        extend_runs(self._runs, end - n + 1,
                    tuple(sim.dynamics.command) if snap and snap.commanded else None, n)
        self._next = end + 1
        self._states.fromlist(list(chain.from_iterable(states)))   # the fastest way in
        self._books.fromlist(with_last(books, sim))
        self._waiting += n
        if self._waiting >= self._check_at:
            self.flush()

    def flush(self, sim=None, force: bool = False) -> None:
        """Send the buffered steps when a send is due: a period of wall time has passed
        (LIVE_PERIOD for a viewer, FILE_PERIOD for a file) or BATCH_STEPS are waiting.
        Cheap to call once per tick (`sim` is accepted for that protocol; the rows already
        know theirs); step_batch() also calls it every CHECK_EVERY (LIVE_CHECK_EVERY) steps."""
        waiting = self._waiting
        mark_wall(self)
        due = force or waiting + self._segment_rows >= BATCH_STEPS or len(
            self._segments) >= SEGMENTS or time.monotonic() - self._last_send >= self._period
        self._check_at = min(waiting + self._check_every, BATCH_STEPS)
        if not (waiting or self._events or self._ticks or self._segments
                or force and self._static.due) or not due:
            return
        close_segment(self)
        batch, self._segments, self._segment_rows = self._segments, [], 0
        self._last_send = time.monotonic()
        if self.enabled:                    # the latest setup's, where it changed
            self._guard(self._static.send, self.stream, self.node, self.stamp_origin_ns, force)
        if self.enabled and not self._sender.put(batch):
            self._warn_once("send", "rerun: the telemetry sender stopped; running on without it")
            self.enabled = False

    def node_ticks(self, sim, ticks) -> None:
        """The node's ticks just handed over: [(sim.steps at the tick's end, story values)]."""
        if sim is self.sim:
            self._ticks += [(self._waiting - 1 - (sim.steps - step), values)
                            for step, values in ticks]

    def _on_sim_event(self, event) -> None:
        """At the step it came in (event.t: its start), though its states come later."""
        self.event(f"{event.kind}: {event.message}", event.level,
                   round(event.t / self.sim.step_size) + 1 - self._next)

    def event(self, text: str, level: str = "info", ahead: int = 0) -> None:
        """A text-log line, sent with the steps: at the next step recorded, or `ahead` steps
        after it (the last one if none follows before a send)."""
        self._events.append((self._waiting + max(ahead, 0), str(text),
                             LEVELS.get(str(level).lower(), rr.TextLogLevel.INFO)))

    def finish(self, sim=None) -> None:
        """Send what is buffered and close the sinks, so a file is complete and verifies."""
        self.flush(force=True)
        self._sender.close()
        if self.sim is not None and self._on_sim_event in self.sim.event_listeners:
            self.sim.event_listeners.remove(self._on_sim_event)
        if self.sinks:                        # closed even after a failure: a whole file
            self._guard(self.stream.flush, timeout_sec=FLUSH_TIMEOUT)
            self._guard(self.stream.disconnect)
        self.enabled = False
        if self.path and self.sinks:
            check_rrd_file(self.path, footer=not self.node)   # a full disk: whole messages

    # -- binding a simulator --------------------------------------------------------------

    def _bind(self, sim) -> bool:
        """Rows buffered so far belong to the previous simulator or dynamics: a segment of
        the batch of their own (read with their snapshot), unless they read alike. Returns whether sim carries on the run (the same simulator,
        not reset: the run's E(0) kept). Its own events go to the text log."""
        previous = self.sim
        carried = sim is previous and sim.steps + 1 >= self._next
        if carried and _alike_carried_on(self, sim):
            return True
        if previous is not None:
            close_segment(self)
            self.flush()        # when due: a held node records no steps, only setups
        initial = self._snapshot.initial if carried and self._snapshot is not None else None
        self.sim, self._dynamics, self._snapshot = sim, sim.dynamics, None
        self._next = sim.steps + carried      # the next step to record
        self._guard(self._describe, sim, initial)
        if sim is not previous:
            if previous is not None and self._on_sim_event in previous.event_listeners:
                previous.event_listeners.remove(self._on_sim_event)
            for earlier in sim.events:
                self._on_sim_event(earlier)
            sim.event_listeners.append(self._on_sim_event)
        return carried

    def _describe(self, sim, initial=None) -> None:
        """Open the sinks (first time); what does not change from step to step (the layout
        too) is logged at the next send (StaticData)."""
        snap = self._snapshot = Snapshot(sim, initial).carry_on(self._described)
        self._described = snap
        snap.arm3d = arm3d_for(sim.scene.links) if drawn(sim.scene.links) else None   # no payload
        if self._layout is None:
            self._layout = self._static.drawn(snap)   # the default blueprint: drawn here
            if open_sinks(self.stream, blueprint(snap, self.live, self.node), self.sinks,
                          self._warn_once, path=self.path, spawn=self.spawn, connect=self.connect,
                          footer=not self.node):
                self.stream.send_recording_name(f"arm_sim {(self.scene or sim.scene).name}")
                self.enabled = True
        self._static.due = (snap, sim)

    # -- sending ------------------------------------------------------------------------

    def _deliver(self, batch) -> None:
        """In the sender thread: each batch in the order flush() queued it."""
        if self.enabled:
            with np.errstate(all="ignore"):   # as in the core: an absurd state's E is inf
                self._guard(self._writer.send_batch, batch)

    # -- failures -----------------------------------------------------------------------

    def _guard(self, action, *args, **kwargs) -> None:
        """Run a logging action; a failure is one warning and telemetry stops, physics does not."""
        try:
            action(*args, **kwargs)
        except Exception as error:
            self._warn_once("send", f"rerun: telemetry failed ({type(error).__name__}: {error}); "
                                    "the simulation runs on without it")
            self.enabled = False

    def _warn_once(self, key: str, message: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            self._warn(message)


def mark_wall(recorder: RerunRecorder) -> None:
    """log_time: the wall clock now at the rows waiting (rows in between interpolated)."""
    if recorder._waiting and (not recorder._walls or recorder._walls[-1][0] != recorder._waiting):
        recorder._walls.append((recorder._waiting, time.time_ns()))


def close_segment(recorder: RerunRecorder) -> None:
    """The rows waiting (read with the snapshot now) join the batch's segments: a physics
    setup's rows, sent with the others of the batch (writer.BatchWriter.send_batch)."""
    r = recorder
    mark_wall(r)
    if r._waiting or r._events or r._ticks:
        r._segments.append((r._snapshot, r._runs, r._states, r._events, r._ticks, r._walls,
                            r._books))
    r._segment_rows += r._waiting
    r._states, r._books, r._runs, r._events = array("d"), array("d"), [], []
    r._ticks, r._walls, r._waiting = [], [], 0
    r._check_at = min(r._check_every, BATCH_STEPS)


def _alike_carried_on(recorder: RerunRecorder, sim) -> bool:
    """A live change its rows do not show (readouts.reads_alike: damping, friction values):
    the batch being filled goes on under the new snapshot, with no send of its own (a
    slider at 100 changes/s would otherwise send ~20 small chunks per change, and rerun
    keeps an index entry per chunk until the file closes). The static data follows at
    the next send."""
    if recorder._snapshot is None:
        return False
    snap = Snapshot(sim, recorder._snapshot.initial).carry_on(recorder._snapshot)
    if not reads_alike(recorder._snapshot, snap):
        return False
    snap.arm3d, recorder._snapshot, recorder._dynamics = recorder._snapshot.arm3d, snap, sim.dynamics
    recorder._described = snap
    recorder._static.due = (snap, sim)
    return True


class SenderThread:
    """The thread that hands each batch flush() queues, in order, to `deliver`; started by
    the first batch, stopped by close() once the queue is empty."""

    def __init__(self, deliver):
        self.deliver = deliver
        self.queue = queue.Queue(maxsize=QUEUED_BATCHES)   # bounds memory: flush() waits
        self.thread = None

    def put(self, batch) -> bool:
        """Queue a batch; False if the thread has died (never wait on a queue nobody empties)."""
        if self.thread is None:
            self.thread = threading.Thread(target=self._run, name="rerun-telemetry", daemon=True)
            self.thread.start()
        if not self.thread.is_alive():
            return False
        self.queue.put(batch)
        return True

    def close(self) -> None:
        if self.thread is not None:
            self.queue.put(None)
            self.thread.join()
            self.thread = None

    def _run(self) -> None:
        while (batch := self.queue.get()) is not None:
            self.deliver(batch)


def extend_runs(runs, first: int, command, n: int) -> None:
    """n steps from `first` under `command` onto the runs waiting (module docstring)."""
    last = runs[-1] if runs else None
    if last is not None and last[0] + last[2] == first and last[1] == command:
        last[2] += n                      # the run goes on: same command, next step
    else:
        runs.append([first, command, n])


def with_last(books, sim) -> list:
    """Error books sampled (flat) and, unless among them, those of sim's last step."""
    if books and books[-4] == sim.steps:
        return list(books)
    return [*books, *error_books(sim)]


def start_line(sim) -> str:
    """The text-log line a run starts with: what runs, and what holds its error."""
    estimate = ("" if sim.error_estimate == sim.error_estimate or sim.scene.estimate == "off"
                else ", no error estimate: the simulator does not estimate these steps")
    return (f"scene {sim.scene.name} start: policy {sim.scene.policy}, effects "
            f"{'+'.join(sim.dynamics.effects) or 'none'}, h = {sim.step_size:g} s, "
            f"{sim.scene.method}, {held_by(sim.scene)}{estimate}, "
            f"E0 = {sim.initial_energy:.9g} J")


def make_recorder(scene=None, path=None, spawn=False, connect=None, application_id="arm_sim",
                  warn=None, stream=None) -> RerunRecorder | None:
    """A recorder writing to `path` (.rrd), a spawned viewer and/or a running viewer at
    `connect`; None when no sink is asked for. The recording is named after `scene`
    (default: the first simulator's); `warn` receives the one-line warnings (default:
    the `arm_sim_ros.recording.rrd.telemetry` logger)."""
    if not (path or spawn or connect):
        return None
    return RerunRecorder(scene, path=path, spawn=spawn, connect=connect,
                         application_id=application_id, warn=warn, stream=stream)
