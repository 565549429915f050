"""A batch of recorded steps onto a Rerun stream: one send_columns per entity.

Every row is on three timelines: sim_time (simulated time running on across resets, as the
node's JointState stamps do), ros_time (the stamp: stamp_origin_ns + sim_time; the offline
run's origin is 0, as its bag's stamps are) and log_time (the wall clock when the recorder
received the row, interpolated between its step_batch calls). The writer keeps what joins
one batch to the next: where the timelines stand and the last tip drawn (the trace joins
consecutive frames, but not across a reset). It runs in the recorder's sender thread, one
batch at a time.

A batch may hold rows of several physics setups (a live change of effort limits, a payload,
a restart), each read with its own snapshot: send_batch() works them out in order and sends
each entity's rows of the whole batch in one send_columns. Rerun keeps an index entry (~2 kB
of memory) per chunk until the file closes, so a chunk per entity per setup would grow a
node's memory with every live change rather than with the time recorded.
"""
from __future__ import annotations

from math import nan

import numpy as np
import rerun as rr

from itertools import chain

from .blueprint import NODE_SERIES
from .columns import nanoseconds, points, scalars, strips, text_lines, time_columns
from ..readouts import accuracy_values, channel_values, drawing_points, drawn, unpack
from .story import TickStory

FRAME_PERIOD = 0.005             # simulated seconds between arm drawings: 200 frames/s is smooth


class BatchWriter:
    """send_batch(segments) for each batch the recorder's flush() queued, in order; each
    segment is send()'s arguments, `snap` (a readouts.Snapshot) how its rows read."""

    def __init__(self, stream):
        self.stream = stream
        self._last_raw = -np.inf  # steps x h of the last row sent
        self._offset = 0.0        # what resets add to steps x h on the timeline
        self._last_ns = 0         # timeline position of the last row sent
        self._last_tip = None
        self._last_wall = None    # log_time of the last row sent, ns
        self.stamp_origin_ns = 0  # ros_time at sim_time 0; None: no ros_time timeline
        self._story = TickStory()  # the node's ticks: refused, late, real-time factor, sub-steps
        self._books_before = (0.0, 0.0)   # (step, substeps_taken) of the last books sent
        self._row_substeps = np.zeros(0)   # sub-steps of each row of the batch (nan: unknown)
        self._held = {}           # (path, build, options, shape) -> [(index, data)] (send_batch)

    def send_batch(self, segments) -> None:
        """The segments of one batch in order, then each entity's rows in one chunk."""
        for segment in segments:
            self.send(*segment)
        self.flush()

    def flush(self) -> None:
        """Send the columns held: one send_columns per entity and column layout."""
        held, self._held = self._held, {}
        for (path, build, options, _), parts in held.items():
            ns = np.concatenate([index[0] for index, _ in parts])
            wall = np.concatenate([index[1] for index, _ in parts])
            data = [data for _, data in parts]
            data = data[0] if len(data) == 1 else (np.concatenate(data) if isinstance(
                data[0], np.ndarray) else list(chain.from_iterable(data)))
            rr.send_columns(path, indexes=self._columns(ns, wall),
                            columns=build(data, *options), recording=self.stream)

    def send(self, snap, runs, states, events, ticks, walls, books) -> None:
        """Runs of [first step, command, steps] with their flattened states, text lines
        (rows waiting before them, text, level) and the node's ticks (row, values), each at
        its row (the last one if none), the wall clock marks of the batch, and the error
        books sampled in it, flattened (readouts.error_books; the batch's last step among
        them, telemetry.with_last). Held until flush()."""
        n = sum(steps for _, _, steps in runs)
        if n:
            steps, states, commands = unpack(runs, states, n)
            self._timeline(steps * snap.step_size)
            self._wall_clock(n, walls)
            self._send_rows(snap, steps, states, commands)
            self._send_accuracy(snap, steps, np.frombuffer(books, float).reshape(-1, 4))
        if events:
            rows = [i for i, _, _ in events]
            self._send_columns("events", self._index(rows, n), text_lines,
                               [(text, level) for _, text, level in events])
        if ticks:
            index = self._index([max(i, 0) for i, _ in ticks], n)
            values = self._story.values([v for _, v in ticks], self._tick_substeps(ticks))
            for k, path in enumerate(NODE_SERIES):
                self._send_columns(path, index, scalars, values[:, k])

    def _send_accuracy(self, snap, steps, books) -> None:
        """The error books sampled in the batch (readouts.accuracy_values), each at its row."""
        values, self._row_substeps, self._books_before = accuracy_values(
            snap, steps, books, self._books_before)
        for path, (rows, column) in values.items():
            if len(rows):
                self._send_columns(path, self._index(rows, len(steps)), scalars, column)

    def _tick_substeps(self, ticks) -> list:
        """Each tick's sub-steps: those of its steps, which end at its row (nan: unknown)."""
        sub = self._row_substeps
        return [float(np.sum(sub[max(row - v[3] + 1, 0):row + 1])) if 0 <= row < len(sub)
                else nan for row, v in ticks]

    def _index(self, rows, n):
        """(sim_time ns, log_time ns) of rows of this batch (clipped to its last; none: the
        last sent)."""
        if not n:            # a batch of lines only: each at the last row sent
            return (np.full(len(rows), self._last_ns, "timedelta64[ns]"),
                    np.full(len(rows), self._last_wall or 0, np.int64))
        at = np.minimum(rows, n - 1)
        return self._row_ns[at], self._row_wall[at]

    def _columns(self, ns, wall):
        return time_columns(np.asarray(ns, "timedelta64[ns]"), np.asarray(wall, "int64"),
                            self.stamp_origin_ns)

    def _wall_clock(self, n, walls) -> None:
        """Each row's log_time: the wall clock of the step_batch call that brought it, rows
        in between interpolated (ns since the epoch)."""
        if not walls:
            self._row_wall = np.full(n, self._last_wall or 0, dtype=np.int64)
            return
        counts = np.array([c for c, _ in walls], float)
        marks = np.array([w for _, w in walls], np.int64)
        base = int(marks[0])
        if counts[0] > 0:    # the batch starts where the last one ended (or at its first mark)
            first = base if self._last_wall is None else self._last_wall
            counts, marks = np.concatenate(([0.0], counts)), np.concatenate(([first], marks))
        self._row_wall = base + np.rint(np.interp(
            np.arange(1, n + 1), counts, (marks - base).astype(float))).astype(np.int64)
        self._last_wall = int(self._row_wall[-1])

    def _send_rows(self, snap, steps, states, commands) -> None:
        index = self._index(np.arange(len(steps)), len(steps))
        values = channel_values(snap, states, commands)
        for path, column in values.items():
            self._send_columns(path, index, scalars, column)
        self._send_drawing(snap, steps, states[:, 0], states[:, 1], values.get("joints/torque"))

    def _timeline(self, t):
        """Each row's position on the timeline in ns: t, plus the simulated time of every run
        before the last reset (a reset shows as time going back to 0)."""
        previous = np.concatenate(([self._last_raw], t[:-1]))
        self._restarted = t <= previous
        offsets = self._offset + np.cumsum(np.where(self._restarted, previous, 0.0))
        self._offset, self._last_raw = float(offsets[-1]), float(t[-1])
        self._row_ns = nanoseconds(t + offsets)
        self._last_ns = self._row_ns[-1]

    def _send_drawing(self, snap, steps, q1, q2, torque=None) -> None:
        """Links, joints and the tip's trace every FRAME_PERIOD of simulated time; the 3D
        arm's joints and torque arrows at the same frames."""
        frames = np.flatnonzero(steps % max(1, round(FRAME_PERIOD / snap.step_size)) == 0)
        if frames.size == 0 or not drawn(snap.arm):
            return
        index = self._index(frames, len(steps))
        elbow, tip = drawing_points(snap.arm, q1[frames], q2[frames])
        base = np.zeros_like(elbow)
        self._send_columns("arm/links", index, strips, np.stack((base, elbow, elbow, tip), 1), 2)
        self._send_columns("arm/joints", index, points, np.stack((base, elbow, tip), 1))
        # The trace joins consecutive frames, but not across a reset.
        previous = np.concatenate(([self._last_tip if self._last_tip is not None else tip[0]],
                                   tip[:-1]))
        restarted = np.flatnonzero(self._restarted[frames])
        previous[restarted] = tip[restarted]
        self._send_columns("arm/tip_trace", index, strips, np.stack((previous, tip), 1))
        self._last_tip = tip[-1]
        if snap.arm3d is not None:
            snap.arm3d.send(self._send_columns, index, q1[frames], q2[frames],
                            None if torque is None else torque[frames])

    def _send_columns(self, path, index, build, data, *options) -> None:
        """`build(data, *options)` on the time columns of `index`, held until flush() with
        the entity's other rows of the batch."""
        shape = data.shape[1:] if isinstance(data, np.ndarray) else ()
        self._held.setdefault((path, build, options, shape), []).append((index, data))
