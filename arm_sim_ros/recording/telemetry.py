"""Rerun telemetry: the explainer's readouts on simulated time, beside a drawing of the arm.

The only module that imports rerun. Recording must never slow or stop the physics:
step_batch() takes a tick's states in one call (step() one step's) and appends them to
one array of doubles; a batch of steps goes to a sender thread, which computes energies,
torques and drawings with numpy and sends one send_columns per entity (rerun encodes the
chunks on threads of its own). What is left on the simulation's side is the copy of the
states and the sender's time holding the GIL; benchmarks/bench_telemetry.py measures both.
A sink that fails (unwritable file, no viewer at the address, a viewer that dies) is one
warning; the simulation runs on.

Channels follow the scene's effects (Simulator.channels): no `energy/dissipated`
without damping, no `work/actuator` or joint torques without an actuator.
"""
from __future__ import annotations

import logging
import os
import queue
import socket
import sys
import threading
import time
from array import array
from itertools import chain
from urllib.parse import urlsplit

import numpy as np
import pyarrow as pa
import rerun as rr
import rerun.blueprint as rrb

TIMELINE = "sim_time"            # steps x step_size; continued across resets, as the node's stamps
FRAME_PERIOD = 0.005             # simulated seconds between arm drawings: 200 frames/s is smooth
TRACE_SECONDS = 2.0              # the tip trace shows this much simulated time up to the cursor
BATCH_STEPS = 20_000             # send at least this often: bounds memory; ~0.1 ms per send_columns
CHECK_EVERY = 256                # steps between looks at the wall clock (file)...
LIVE_CHECK_EVERY = 8             # ...and for a viewer: a node may take one step per tick
FILE_PERIOD = 1.0                # wall seconds between sends to a file...
LIVE_PERIOD = 0.1                # ...and to a viewer, which a person is watching
FLUSH_TIMEOUT = 2.0              # wall seconds finish() waits for a sink before giving up on it
QUEUED_BATCHES = 8               # batches queued before flush() waits: bounds memory
DEFAULT_PORT = 9876

# Bright enough for the viewer's dark theme; one colour per readout wherever it appears.
# Names use only glyphs the viewer's font has (a missing one, e.g. ᵀ, crashes the viewer).
ENERGY_SERIES = {
    "energy/kinetic": ("kinetic T", (255, 170, 60)),
    "energy/potential": ("potential V", (90, 180, 255)),
    "energy/total": ("total E = T + V", (245, 245, 245)),
    "energy/dissipated": ("dissipated ∫d|q̇|²dt", (255, 95, 125)),
    "work/actuator": ("actuator work ∫τ·q̇dt", (110, 230, 110)),
    "energy/balance_residual": ("residual E−E₀−W+dissipated", (225, 120, 255)),
}
JOINT_SERIES = {
    "joints/angle": ("angle (rad)", ("q1 shoulder", "q2 elbow")),
    "joints/velocity": ("velocity (rad/s)", ("q̇1 shoulder", "q̇2 elbow")),
    "joints/torque": ("applied torque (N m)", ("τ1 shoulder", "τ2 elbow")),
}
JOINT_COLORS = ((80, 220, 235), (255, 205, 70))      # shoulder cyan, elbow amber
TRACE_COLOR = (190, 190, 190)     # neutral: violet is the residual's
HORIZON_COLOR = (100, 100, 100)
LEVELS = {"debug": rr.TextLogLevel.DEBUG, "info": rr.TextLogLevel.INFO,
          "warn": rr.TextLogLevel.WARN, "warning": rr.TextLogLevel.WARN,
          "error": rr.TextLogLevel.ERROR}


def energies(arm, gravity: float, q1, q2, u1, u2):
    """Kinetic and potential energy of many states: model.kinetic_energy and
    model.potential_energy term for term, in numpy (the scalar calls cost more than
    the RK4 step itself; see benchmarks/bench_telemetry.py)."""
    a, b, d = arm.inertia_coefficients
    k1, k2 = arm.gravity_coefficients
    c2 = np.cos(q2)
    m11 = a + 2.0 * b * c2
    m12 = d + b * c2
    kinetic = 0.5 * (m11 * u1 * u1 + 2.0 * m12 * u1 * u2 + d * u2 * u2)
    potential = gravity * (k1 * np.sin(q1) + k2 * np.sin(q1 + q2))
    return kinetic, potential


def gravity_torques(arm, gravity: float, q1, q2):
    """model.gravity_torque for many configurations, as an (n, 2) array."""
    k1, k2 = arm.gravity_coefficients
    g2 = gravity * k2 * np.cos(q1 + q2)
    return np.column_stack((gravity * k1 * np.cos(q1) + g2, g2))


def drawing_points(arm, q1, q2):
    """Elbow and tip of many configurations, y negated: the viewer's 2D y axis points down."""
    l1, l2 = arm.link_lengths
    elbow = np.column_stack((l1 * np.cos(q1), -l1 * np.sin(q1)))
    tip = elbow + np.column_stack((l2 * np.cos(q1 + q2), -l2 * np.sin(q1 + q2)))
    return elbow, tip


def energy_paths(channels) -> list[str]:
    """The scalar channels a scene with these integrated channels produces."""
    paths = ["energy/kinetic", "energy/potential", "energy/total"]
    if "dissipated" in channels:
        paths.append("energy/dissipated")
    if "work" in channels:
        paths.append("work/actuator")
    return paths + ["energy/balance_residual"]


def joint_paths(channels) -> list[str]:
    return ["joints/angle", "joints/velocity"] + (["joints/torque"] if "work" in channels else [])


def blueprint(arm, channels, live: bool) -> rrb.Blueprint:
    """Arm and events on the left; energy, work with residual, and joints on the right."""
    reach = 1.1 * sum(arm.link_lengths)
    energy = [p for p in ("energy/kinetic", "energy/potential", "energy/total", "energy/dissipated")
              if p in energy_paths(channels)]
    balance = [p for p in ("work/actuator", "energy/dissipated", "energy/balance_residual")
               if p in energy_paths(channels)]
    trace_range = rrb.VisibleTimeRanges(
        timeline=TIMELINE, start=rrb.TimeRangeBoundary.cursor_relative(seconds=-TRACE_SECONDS),
        end=rrb.TimeRangeBoundary.cursor_relative(seconds=0.0))
    arm_view = rrb.Spatial2DView(
        name="Arm (y up, V = 0 on the grey line)", origin="arm",
        visual_bounds=rrb.VisualBounds2D(x_range=[-reach, reach], y_range=[-reach, reach]),
        overrides={"arm/tip_trace": trace_range})
    plots = [rrb.TimeSeriesView(name="Energy (J)", contents=energy,
                                plot_legend=rrb.PlotLegend(rrb.Corner2D.LeftTop)),
             rrb.TimeSeriesView(name="Work, dissipation and balance residual (J)", contents=balance,
                                plot_legend=rrb.PlotLegend(rrb.Corner2D.LeftTop))]
    joints = [rrb.TimeSeriesView(name=f"Joint {JOINT_SERIES[p][0]}", origin=p)
              for p in joint_paths(channels)]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(arm_view, rrb.TextLogView(name="Events", origin="events"),
                         row_shares=[4, 1]),
            rrb.Vertical(*plots, rrb.Horizontal(*joints), row_shares=[3, 3, 2]),
            column_shares=[2, 3]),
        rrb.TimePanel(timeline=TIMELINE, play_state="following" if live else "paused",
                      state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
    )


def viewer_url(address: str) -> str:
    """`host:port`, `rerun+http://host:port/proxy` or a bare port -> the gRPC URL rerun takes."""
    text = address.strip()
    if text.isdigit():
        text = f"127.0.0.1:{text}"
    if "://" not in text:
        text = f"rerun+http://{text}/proxy"
    return text


def viewer_reachable(url: str, timeout: float = 0.5) -> bool:
    """A quick TCP check: rerun's own connect blocks ~5 s and then drops data silently."""
    parts = urlsplit(url)
    try:
        with socket.create_connection((parts.hostname or "127.0.0.1", parts.port or DEFAULT_PORT),
                                      timeout=timeout):
            return True
    except (OSError, ValueError):
        return False


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
        self._last_raw = -np.inf  # steps x h of the last row sent
        self._offset = 0.0        # what resets add to steps x h on the timeline
        self._last_ns = 0         # timeline position of the last row sent
        self._last_tip = None
        self._layout = None       # what the blueprint was drawn for: (channels, arm)
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
        if sim is not self.sim:
            self._bind(sim)
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
        batch = (self.sim, self._runs, self._states, self._events)
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

    # -- sinks --------------------------------------------------------------------------

    def _open_sinks(self, sim) -> None:
        """Open the sinks asked for; each failure is a warning and that sink is skipped."""
        board = blueprint(sim.arm, sim.channels, self.live)
        sinks = []
        if self.path:
            try:
                open(self.path, "wb").close()
                sinks.append(rr.FileSink(str(self.path)))
                self.sinks.append(f"file {self.path}")
            except OSError as error:
                self._warn_once("file", f"rerun: cannot write {self.path} ({error.strerror}); "
                                        "the simulation runs on without that recording")
        if self.spawn:
            self._spawn_viewer(sinks)
        if self.connect:
            url = viewer_url(self.connect)
            if viewer_reachable(url):
                sinks.append(rr.GrpcSink(url))
                self.sinks.append(f"viewer {url}")
            else:
                self._warn_once("connect", f"rerun: no viewer answers at {url}; running on "
                                           "without it (start `rerun` first)")
        if sinks:
            rr.set_sinks(*sinks, default_blueprint=board, recording=self.stream)
            self.stream.send_recording_name(f"arm_sim {(self.scene or sim.scene).name}")
            self.enabled = True

    def _spawn_viewer(self, sinks) -> None:
        """A viewer on DEFAULT_PORT; rerun only logs when one fails to come up, so check."""
        url = viewer_url(str(DEFAULT_PORT))
        if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                     or os.environ.get("WAYLAND_DISPLAY")):
            self._warn_once("spawn", "rerun: no display to spawn a viewer on (DISPLAY is unset); "
                                     "running on without it")
            return
        try:
            rr.spawn(port=DEFAULT_PORT, connect=False, recording=self.stream)
        except Exception as error:
            self._warn_once("spawn", f"rerun: cannot spawn a viewer ({error}); running on")
            return
        if not viewer_reachable(url):
            self._warn_once("spawn", "rerun: the spawned viewer did not come up; running on "
                                     "without it")
            return
        sinks.append(rr.GrpcSink(url))
        self.sinks.append("spawned viewer")

    def _bind(self, sim) -> None:
        """Rows buffered so far belong to the previous simulator: send them first. The
        simulator's own events (sub-stepping, refused steps) go to the text log."""
        previous = self.sim
        if previous is not None:
            self.flush(force=True)
        self.sim = sim
        self._commanded = sim.scene.policy.startswith("command")
        self._guard(self._describe, sim)
        if sim is not previous:
            if previous is not None and self._on_sim_event in previous.event_listeners:
                previous.event_listeners.remove(self._on_sim_event)
            for earlier in sim.events:
                self._on_sim_event(earlier)
            sim.event_listeners.append(self._on_sim_event)

    def _describe(self, sim) -> None:
        """Open the sinks (first time) and log what does not change from step to step."""
        layout = (sim.channels, sim.arm)
        if self._layout is None:
            self._open_sinks(sim)
        elif layout != self._layout and self.enabled:
            rr.send_blueprint(blueprint(sim.arm, sim.channels, self.live), recording=self.stream)
        self._layout = layout
        if not self.enabled:
            return
        log = self.stream.log
        for path in energy_paths(sim.channels):
            name, color = ENERGY_SERIES[path]
            log(path, rr.SeriesLines(names=[name], colors=[color], widths=[2.0]), static=True)
        for path in joint_paths(sim.channels):
            log(path, rr.SeriesLines(names=list(JOINT_SERIES[path][1]), colors=list(JOINT_COLORS),
                                     widths=[2.0, 2.0]), static=True)
        reach = 1.1 * sum(sim.arm.link_lengths)
        log("arm/horizon", rr.LineStrips2D([[(-reach, 0.0), (reach, 0.0)]], colors=[HORIZON_COLOR],
                                           radii=[0.004], draw_order=0.0), static=True)
        log("arm/links", rr.LineStrips2D.from_fields(colors=list(JOINT_COLORS), radii=[0.035],
                                                     draw_order=[20.0]), static=True)
        log("arm/joints", rr.Points2D.from_fields(colors=[(245, 245, 245)], radii=[0.05],
                                                  draw_order=[30.0]), static=True)
        log("arm/tip_trace", rr.LineStrips2D.from_fields(colors=[TRACE_COLOR], radii=[0.008],
                                                         draw_order=[10.0]), static=True)

    # -- sending ------------------------------------------------------------------------

    def _send_batches(self) -> None:
        """The sender thread: batches in the order flush() queued them, until finish()."""
        while (batch := self._batches.get()) is not None:
            if self.enabled:
                with np.errstate(all="ignore"):   # as in the core: an absurd state's E is inf
                    self._guard(self._send, *batch)

    def _send(self, sim, runs, states, events) -> None:
        n = sum(steps for _, _, steps in runs)
        if n:
            self._send_rows(sim, *_unpack(runs, states, n))
        if events:
            at = [self._row_ns[min(i, n - 1)] if n else self._last_ns for i, _, _ in events]
            self._send_columns("events", [_time_column(np.array(at))], rr.TextLog.columns(
                text=[text for _, text, _ in events], level=[level for _, _, level in events]))

    def _send_rows(self, sim, steps, states, commands) -> None:
        index = [_time_column(self._timeline(steps * sim.step_size))]
        q1, q2, u1, u2 = states[:, 0], states[:, 1], states[:, 2], states[:, 3]
        kinetic, potential = energies(sim.arm, sim.scene.gravity, q1, q2, u1, u2)
        total = kinetic + potential
        books = {name: states[:, 4 + i] for i, name in enumerate(sim.channels)}
        work = books.get("work", 0.0)
        dissipated = books.get("dissipated", 0.0)
        values = {"energy/kinetic": kinetic, "energy/potential": potential, "energy/total": total,
                  "energy/balance_residual": total - sim.initial_energy - work + dissipated,
                  "joints/angle": states[:, 0:2], "joints/velocity": states[:, 2:4]}
        if "dissipated" in books:
            values["energy/dissipated"] = dissipated
        if "work" in books:
            values["work/actuator"] = work
            values["joints/torque"] = _torques(sim, q1, q2, commands)
        for path, column in values.items():
            self._send_columns(path, index, _scalars(column))
        self._send_drawing(sim, steps, q1, q2)

    def _timeline(self, t):
        """Each row's position on the timeline in ns: t, plus the simulated time of every run
        before the last reset (a reset shows as time going back to 0)."""
        previous = np.concatenate(([self._last_raw], t[:-1]))
        self._restarted = t <= previous
        offsets = self._offset + np.cumsum(np.where(self._restarted, previous, 0.0))
        self._offset, self._last_raw = float(offsets[-1]), float(t[-1])
        self._row_ns = _nanoseconds(t + offsets)
        self._last_ns = self._row_ns[-1]
        return self._row_ns

    def _send_drawing(self, sim, steps, q1, q2) -> None:
        """Links, joints and the tip's trace every FRAME_PERIOD of simulated time."""
        frames = np.flatnonzero(steps % max(1, round(FRAME_PERIOD / sim.step_size)) == 0)
        if frames.size == 0:
            return
        index = [_time_column(self._row_ns[frames])]
        elbow, tip = drawing_points(sim.arm, q1[frames], q2[frames])
        base = np.zeros_like(elbow)
        self._send_columns("arm/links", index, _strips(
            np.stack((base, elbow, elbow, tip), 1), strips_per_row=2))
        self._send_columns("arm/joints", index, _points(np.stack((base, elbow, tip), 1)))
        # The trace joins consecutive frames, but not across a reset.
        previous = np.concatenate(([self._last_tip if self._last_tip is not None else tip[0]],
                                   tip[:-1]))
        restarted = np.flatnonzero(self._restarted[frames])
        previous[restarted] = tip[restarted]
        self._send_columns("arm/tip_trace", index, _strips(np.stack((previous, tip), 1)))
        self._last_tip = tip[-1]

    def _send_columns(self, path, index, columns) -> None:
        rr.send_columns(path, indexes=index, columns=columns, recording=self.stream)

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


def _torques(sim, q1, q2, commands):
    """The applied torque per row, as sim.dynamics.applied_torque gives it at that step
    (`commands`: the held command of each row, for the command policies)."""
    scene, n = sim.scene, len(q1)
    if commands is not None:
        tau = commands.reshape(n, 2)
    else:
        tau = np.tile(sim.dynamics.applied_torque((0.0, 0.0)), (n, 1)).astype(float)
    if scene.policy.endswith("gravity_compensation") and scene.gravity != 0.0:
        tau = (0.0 if scene.policy == "gravity_compensation" else tau) + gravity_torques(
            sim.arm, scene.gravity, q1, q2)
    return tau


def _unpack(runs, states, n):
    """Runs of [first step, command, steps] (n steps in all) and their flattened states as
    arrays: step numbers (n,), states (n, width), commands (n, 2) or None."""
    states = np.frombuffer(states, float).reshape(n, -1)
    lengths = np.array([count for _, _, count in runs])
    firsts = np.array([first for first, _, _ in runs]) - (np.cumsum(lengths) - lengths)
    steps = np.arange(n) + np.repeat(firsts, lengths)
    commands = (np.repeat(np.array([c for _, c, _ in runs], float), lengths, axis=0)
                if runs[0][1] is not None else None)
    return steps, states, commands


def _time_column(ns):
    return rr.TimeColumn(TIMELINE, duration=ns)


# Columns are built as Arrow directly: rerun's Archetype.columns() converts through Python
# (strip by strip for line strips) and costs 3-10x as much; this runs in the sender thread,
# where every microsecond holding the GIL is one the simulation waits for.

def _column(descriptor, batch, items: int, per_row: int):
    """`items` components of `batch`, `per_row` of them in each row."""
    offsets = np.arange(0, items + 1, per_row, dtype=np.int32)
    return [rr.ComponentColumn(descriptor, batch, offsets=offsets)]


def _scalars(values):
    """A Scalars column: one row per entry of (n,) values, or per row of (n, k)."""
    flat = np.ascontiguousarray(values, dtype=float).reshape(-1)
    return _column(rr.Scalars.descriptor_scalars(), rr.components.ScalarBatch(pa.array(flat)),
                   flat.size, flat.size // len(values))


def _vertices(points, kind):
    """(..., 2) points as Arrow float32 pairs of `kind`."""
    flat = pa.array(np.ascontiguousarray(points, dtype=np.float32).reshape(-1))
    return pa.FixedSizeListArray.from_arrays(flat, type=kind)


def _points(points):
    """(rows, k, 2) points as a Points2D positions column of k points per row."""
    kind = rr.components.Position2DBatch._ARROW_DATATYPE
    rows, k = points.shape[:2]
    return _column(rr.Points2D.descriptor_positions(),
                   rr.components.Position2DBatch(_vertices(points, kind)), rows * k, k)


def _strips(points, strips_per_row=1):
    """Two-point line strips, (rows, 2 x strips_per_row, 2) points, as one LineStrips2D
    column."""
    kind = rr.components.LineStrip2DBatch._ARROW_DATATYPE
    count = points.shape[0] * strips_per_row
    strips = pa.ListArray.from_arrays(pa.array(np.arange(0, 2 * count + 1, 2, dtype=np.int32)),
                                      _vertices(points, kind.value_type), type=kind)
    return _column(rr.LineStrips2D.descriptor_strips(), rr.components.LineStrip2DBatch(strips),
                   count, strips_per_row)


def _nanoseconds(seconds):
    """Simulated seconds as the timeline's integer nanoseconds (exact for steps x h)."""
    return np.rint(seconds * 1e9).astype("timedelta64[ns]")


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
