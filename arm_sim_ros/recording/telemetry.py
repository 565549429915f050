"""Rerun telemetry: the explainer's readouts on simulated time, beside a drawing of the arm.

rerun is imported only in recording/: blueprint.py names the channels and lays out the
viewer, sinks.py opens the file and the viewers, readouts.py computes a batch's values,
columns.py encodes them and writer.py sends them; this module holds the recorder that the
node and `arm-sim run` drive.

Recording must never slow or stop the physics: step_batch() takes a tick's states in one
call (step() one step's) and appends them to one array of doubles; a batch of steps goes
to a sender thread, which computes energies, torques and drawings with numpy and sends one
send_columns per entity (rerun encodes the chunks on threads of its own). What is left on
the simulation's side is the copy of the states and the sender's time holding the GIL;
benchmarks/bench_telemetry.py measures both. A sink that fails (unwritable file, no viewer
at the address, a viewer that dies) is one warning; the simulation runs on.
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

from .blueprint import blueprint, styles
from .readouts import Snapshot
from .sinks import open_sinks
from .writer import BatchWriter

BATCH_STEPS = 20_000             # send at least this often: bounds memory; ~0.1 ms per send_columns
CHECK_EVERY = 256                # steps between looks at the wall clock (file)...
LIVE_CHECK_EVERY = 8             # ...and for a viewer: a node may take one step per tick
FILE_PERIOD = 1.0                # wall seconds between sends to a file...
LIVE_PERIOD = 0.1                # ...and to a viewer, which a person is watching
FLUSH_TIMEOUT = 2.0              # wall seconds finish() waits for a sink before giving up on it
QUEUED_BATCHES = 8               # batches queued before flush() waits: bounds memory
LEVELS = {"debug": rr.TextLogLevel.DEBUG, "info": rr.TextLogLevel.INFO,
          "warn": rr.TextLogLevel.WARN, "warning": rr.TextLogLevel.WARN,
          "error": rr.TextLogLevel.ERROR}


class RerunRecorder:
    """A recorder for cli.RUN_RECORDERS and the node: start / step or step_batch / flush /
    event / finish.

    start(sim) may be called again after a reset or for a new Simulator (step() also
    notices a new one). Simulated time going back (a reset) continues the timeline from
    where the last run ended, as the node's JointState stamps do, and the trace breaks.
    """

    def __init__(self, scene, path=None, spawn=False, connect=None, application_id="arm_sim",
                 warn=None):
        self.scene = scene
        self.path, self.spawn, self.connect = path, spawn, connect
        self.live = bool(spawn or connect)
        self._warn = warn or logging.getLogger(__name__).warning
        self._warned = set()
        self.stream = rr.RecordingStream(application_id)
        self.sinks = []           # descriptions of the sinks that opened
        self.enabled = False
        self.sim = None
        self._snapshot = None     # how the steps waiting read: sim's layout when they were taken
        self._dynamics = None     # sim.dynamics then (a payload grasped rebuilds it)
        # Steps waiting to be sent: their states flattened into one array of doubles (8 bytes
        # a number rather than ~40 as tuples of floats kept alive, and nothing left to convert
        # while holding the GIL in the sender), and runs of consecutive steps under one held
        # command: [first step, command (None without a command policy), steps].
        self._states, self._runs, self._events = array("d"), [], []   # ...and text lines
        self._waiting = 0                       # steps in self._runs
        self._check_every = LIVE_CHECK_EVERY if self.live else CHECK_EVERY
        self._check_at = self._check_every
        self._period = LIVE_PERIOD if self.live else FILE_PERIOD
        self._last_send = time.monotonic()
        self._writer = BatchWriter(self.stream)   # the sender thread's: timeline and trace
        self._layout = None       # what the blueprint was drawn for: Snapshot.key
        self._batches = queue.Queue(maxsize=QUEUED_BATCHES)
        self._sender = None

    # -- protocol ---------------------------------------------------------------------

    def start(self, sim) -> None:
        """Begin (or, after a reset or for a new Simulator, continue) with sim's initial row."""
        self._bind(sim)
        self.event(f"scene {sim.scene.name} start: policy {sim.scene.policy}, effects "
                   f"{'+'.join(sim.dynamics.effects) or 'none'}, h = {sim.step_size:g} s, "
                   f"{sim.scene.integrator}, E0 = {sim.initial_energy:.9g} J")
        self.step(sim)

    def step(self, sim) -> None:
        """After a physics step: keep its state (see step_batch)."""
        self.step_batch(sim, (sim.state,))

    def step_batch(self, sim, states) -> None:
        """After len(states) physics steps: their states in order, the last being sim.state,
        taken under the command sim holds now (the node hands its steps over before a new
        command). The node calls this every 10 steps, `arm-sim run` every 1000; the states
        are copied, so the caller may reuse the list. Nothing else happens here (see flush)."""
        if sim is not self.sim or sim.dynamics is not self._dynamics:
            self._bind(sim, rebuilt=sim is self.sim)
        n = len(states)
        if n == 0:
            return
        first = sim.steps - n + 1
        command = tuple(sim.dynamics.command) if self._commanded else None
        last = self._runs[-1] if self._runs else None
        if last is not None and last[0] + last[2] == first and last[1] == command:
            last[2] += n                      # the run goes on: same command, next step
        else:
            self._runs.append([first, command, n])
        self._states.fromlist(list(chain.from_iterable(states)))   # the fastest way in
        self._waiting += n
        if self._waiting >= self._check_at:
            self.flush()

    def flush(self, sim=None, force: bool = False) -> None:
        """Send the buffered steps when a send is due: a period of wall time has passed
        (LIVE_PERIOD for a viewer, FILE_PERIOD for a file) or BATCH_STEPS are waiting.
        Cheap to call once per tick (`sim` is accepted for that protocol; the rows already
        know theirs); step_batch() also calls it every CHECK_EVERY (LIVE_CHECK_EVERY) steps."""
        waiting = self._waiting
        due = force or waiting >= BATCH_STEPS or time.monotonic() - self._last_send >= self._period
        self._check_at = min(waiting + self._check_every, BATCH_STEPS)
        if not (waiting or self._events) or not due:
            return
        batch = (self._snapshot, self._runs, self._states, self._events)
        self._states, self._runs, self._events, self._waiting = array("d"), [], [], 0
        self._check_at = min(self._check_every, BATCH_STEPS)
        self._last_send = time.monotonic()
        if not self.enabled:
            return
        if self._sender is None:
            self._sender = threading.Thread(target=self._send_batches, name="rerun-telemetry",
                                            daemon=True)
            self._sender.start()
        if not self._sender.is_alive():   # never wait on a queue nobody empties
            self._warn_once("send", "rerun: the telemetry sender stopped; running on without it")
            self.enabled = False
            return
        self._batches.put(batch)

    def _on_sim_event(self, event) -> None:
        self.event(f"{event.kind}: {event.message}",
                   level="error" if event.kind == "fault" else "warn")

    def event(self, text: str, level: str = "info") -> None:
        """A text-log line, sent with the steps: at the next step recorded (the last one if
        none follows before a send)."""
        self._events.append((self._waiting, str(text),
                             LEVELS.get(str(level).lower(), rr.TextLogLevel.INFO)))

    def finish(self, sim=None) -> None:
        """Send what is buffered and close the sinks, so a file is complete and verifies."""
        self.flush(force=True)
        if self._sender is not None:
            self._batches.put(None)
            self._sender.join()
            self._sender = None
        if self.sim is not None and self._on_sim_event in self.sim.event_listeners:
            self.sim.event_listeners.remove(self._on_sim_event)
        if self.enabled:
            self._guard(self.stream.flush, timeout_sec=FLUSH_TIMEOUT)
            self._guard(self.stream.disconnect)
        self.enabled = False

    # -- binding a simulator --------------------------------------------------------------

    def _bind(self, sim, rebuilt: bool = False) -> None:
        """Rows buffered so far belong to the previous simulator (or to sim's dynamics
        before a payload change, `rebuilt`, which keeps the run's E(0)): send them first.
        The simulator's own events (sub-stepping, refused steps) go to the text log."""
        previous = self.sim
        if previous is not None:
            self.flush(force=True)
        initial = self._snapshot.initial if rebuilt and self._snapshot is not None else None
        self.sim, self._dynamics, self._snapshot = sim, sim.dynamics, None
        self._commanded = sim.scene.policy.startswith("command")
        self._guard(self._describe, sim, initial)
        if sim is not previous:
            if previous is not None and self._on_sim_event in previous.event_listeners:
                previous.event_listeners.remove(self._on_sim_event)
            for earlier in sim.events:
                self._on_sim_event(earlier)
            sim.event_listeners.append(self._on_sim_event)

    def _describe(self, sim, initial=None) -> None:
        """Open the sinks (first time) and log what does not change from step to step."""
        snap = self._snapshot = Snapshot(sim, initial)
        layout = snap.key
        if self._layout is None:
            board = blueprint(snap, self.live)
            if open_sinks(self.stream, board, self.sinks, self._warn_once, path=self.path,
                          spawn=self.spawn, connect=self.connect):
                self.stream.send_recording_name(f"arm_sim {(self.scene or sim.scene).name}")
                self.enabled = True
        elif layout != self._layout and self.enabled:
            rr.send_blueprint(blueprint(snap, self.live), recording=self.stream)
        self._layout = layout
        if not self.enabled:
            return
        for path, archetype in styles(snap):
            self.stream.log(path, archetype, static=True)

    # -- sending ------------------------------------------------------------------------

    def _send_batches(self) -> None:
        """The sender thread: batches in the order flush() queued them, until finish()."""
        while (batch := self._batches.get()) is not None:
            if self.enabled:
                with np.errstate(all="ignore"):   # as in the core: an absurd state's E is inf
                    self._guard(self._send, *batch)

    def _send(self, snap, runs, states, events) -> None:
        """One batch, as flush() queued it."""
        self._writer.send(snap, runs, states, events)

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


def make_recorder(scene=None, path=None, spawn=False, connect=None, application_id="arm_sim",
                  warn=None) -> RerunRecorder | None:
    """A recorder writing to `path` (.rrd), a spawned viewer and/or a running viewer at
    `connect`; None when no sink is asked for. The recording is named after `scene`
    (default: the first simulator's); `warn` receives the one-line warnings (default:
    the `arm_sim_ros.recording.telemetry` logger)."""
    if not (path or spawn or connect):
        return None
    return RerunRecorder(scene, path=path, spawn=spawn, connect=connect,
                         application_id=application_id, warn=warn)
