"""A batch of recorded steps onto a Rerun stream: one send_columns per entity.

The writer keeps what joins one batch to the next: where the timeline stands (simulated
time running on across resets, as the node's JointState stamps do) and the last tip drawn
(the trace joins consecutive frames, but not across a reset). It runs in the recorder's
sender thread, one batch at a time.
"""
from __future__ import annotations

import numpy as np
import rerun as rr

from .columns import nanoseconds, points, scalars, strips, time_column
from .readouts import channel_values, drawing_points, unpack

FRAME_PERIOD = 0.005             # simulated seconds between arm drawings: 200 frames/s is smooth


class BatchWriter:
    """send(snap, runs, states, events) for each batch the recorder's flush() queued, in
    order; `snap` (a readouts.Snapshot) is how its rows read."""

    def __init__(self, stream):
        self.stream = stream
        self._last_raw = -np.inf  # steps x h of the last row sent
        self._offset = 0.0        # what resets add to steps x h on the timeline
        self._last_ns = 0         # timeline position of the last row sent
        self._last_tip = None

    def send(self, snap, runs, states, events) -> None:
        """Runs of [first step, command, steps] with their flattened states, and text lines
        (rows waiting before them, text, level), each at its row (the last one if none)."""
        n = sum(steps for _, _, steps in runs)
        if n:
            self._send_rows(snap, *unpack(runs, states, n))
        if events:
            at = [self._row_ns[min(i, n - 1)] if n else self._last_ns for i, _, _ in events]
            self._send_columns("events", [time_column(np.array(at))], rr.TextLog.columns(
                text=[text for _, text, _ in events], level=[level for _, _, level in events]))

    def _send_rows(self, snap, steps, states, commands) -> None:
        index = [time_column(self._timeline(steps * snap.step_size))]
        for path, column in channel_values(snap, states, commands).items():
            self._send_columns(path, index, scalars(column))
        self._send_drawing(snap, steps, states[:, 0], states[:, 1])

    def _timeline(self, t):
        """Each row's position on the timeline in ns: t, plus the simulated time of every run
        before the last reset (a reset shows as time going back to 0)."""
        previous = np.concatenate(([self._last_raw], t[:-1]))
        self._restarted = t <= previous
        offsets = self._offset + np.cumsum(np.where(self._restarted, previous, 0.0))
        self._offset, self._last_raw = float(offsets[-1]), float(t[-1])
        self._row_ns = nanoseconds(t + offsets)
        self._last_ns = self._row_ns[-1]
        return self._row_ns

    def _send_drawing(self, snap, steps, q1, q2) -> None:
        """Links, joints and the tip's trace every FRAME_PERIOD of simulated time."""
        frames = np.flatnonzero(steps % max(1, round(FRAME_PERIOD / snap.step_size)) == 0)
        if frames.size == 0:
            return
        index = [time_column(self._row_ns[frames])]
        elbow, tip = drawing_points(snap.arm, q1[frames], q2[frames])
        base = np.zeros_like(elbow)
        self._send_columns("arm/links", index, strips(
            np.stack((base, elbow, elbow, tip), 1), strips_per_row=2))
        self._send_columns("arm/joints", index, points(np.stack((base, elbow, tip), 1)))
        # The trace joins consecutive frames, but not across a reset.
        previous = np.concatenate(([self._last_tip if self._last_tip is not None else tip[0]],
                                   tip[:-1]))
        restarted = np.flatnonzero(self._restarted[frames])
        previous[restarted] = tip[restarted]
        self._send_columns("arm/tip_trace", index, strips(np.stack((previous, tip), 1)))
        self._last_tip = tip[-1]

    def _send_columns(self, path, index, columns) -> None:
        rr.send_columns(path, indexes=index, columns=columns, recording=self.stream)
