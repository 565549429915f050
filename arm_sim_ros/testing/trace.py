"""A closed loop's trace, and what a controller's author asserts on it.

One row per state, from t = 0: the time, the truth (q, qd), what the controller read
(`measured_q`, `measured_qd`: the sensors' readings, the truth where the scene has none),
the command it gave there (held to its next answer; NaN at a last state not yet
answered), the torque the joints were receiving
there (`tau`: under the command before, as the node publishes it with the state), the
reference it tracked (if given) and the energy books (kinetic, stored, inputs, losses,
residual). In process (loop.py) and over the wire (wire.py) alike.

The figures come from physics/metrics.py, the one definition a sweep tabulates too; each
assertion helper says, when it fails, which figure missed by how much, and the test's
evidence (evidence.py) says where the trace, its recording and its plot are.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..physics.metrics import SETTLE_FRACTION, Performance

COLUMNS = ("t", "q1", "q2", "qd1", "qd2", "measured_q1", "measured_q2", "measured_qd1",
           "measured_qd2", "command1", "command2", "tau1", "tau2", "reference1", "reference2",
           "kinetic", "stored", "inputs", "losses", "residual")
BOOKS = COLUMNS[-5:]


@dataclass
class Trace:
    """Arrays of one closed loop, row k at time t[k] (see the module docstring)."""

    t: np.ndarray
    q: np.ndarray                   # (N, 2) rad, the truth
    qd: np.ndarray                  # (N, 2) rad/s
    measured_q: np.ndarray          # (N, 2) what the controller read
    measured_qd: np.ndarray
    command: np.ndarray             # (N, 2) N m, or rad / rad/s for set-points
    tau: np.ndarray                 # (N, 2) N m the joints received
    books: dict                     # kinetic, stored, inputs, losses, residual: (N,) J
    reference: np.ndarray | None = None     # (N, 2) rad, what the controller tracked
    scene: str = ""
    evidence: dict = field(default_factory=dict)   # {"csv" | "rrd" | "png": path}

    def __len__(self) -> int:
        return len(self.t)

    # -- the figures ------------------------------------------------------------------------

    def figures(self, reference=None, **options) -> dict:
        """physics/metrics.py's figures, per joint (peak_torque, overshoot, settle_time,
        tracking_error, steady_state_error); `options`: band, after, window."""
        return _figures(self, self._reference(reference), **options)

    def settle_time(self, band=None, reference=None) -> float:
        """The later joint's settle time (s): |q - reference| within `band` (rad; default
        2 % of the move) from then to the end; inf if it never settles."""
        settle = self.figures(reference, band=band)["settle_time"]
        return float(np.inf) if np.isnan(settle).any() else float(settle.max())

    def overshoot(self, reference=None) -> float:
        """The largest overshoot of either joint past its reference, rad."""
        return float(self.figures(reference, band=np.inf)["overshoot"].max())

    def steady_state_error(self, window: float | None = None, reference=None) -> float:
        """The larger joint's mean |q - reference| over the last `window` s (default: the
        last tenth of the trace), rad."""
        return float(self.figures(reference, band=np.inf, window=window)
                     ["steady_state_error"].max())

    def tracking_error(self, after: float = 0.0, reference=None) -> float:
        """The larger joint's root mean square of q - reference over t >= after, rad."""
        return float(self.figures(reference, band=np.inf, after=after)
                     ["tracking_error"].max())

    def peak_torque(self) -> float:
        """The largest |torque| either joint received, N m."""
        return float(np.abs(self.tau).max())

    def books_closed(self, tolerance: float = 1e-4) -> bool:
        """Whether the energy books close: |residual| within `tolerance` of the energy in
        play (the largest of the kinetic, stored and booked energies seen) at every row."""
        return self.books_gap() <= tolerance

    def books_gap(self) -> float:
        """The largest |residual| over the energy in play (see books_closed)."""
        b = self.books
        in_play = max(np.abs(b["kinetic"]).max(), np.abs(b["stored"] - b["stored"][0]).max(),
                      np.abs(b["inputs"]).max(), np.abs(b["losses"]).max(), 1e-12)
        return float(np.abs(b["residual"]).max() / in_play)

    def _reference(self, reference) -> np.ndarray:
        if reference is not None:
            reference = np.asarray(reference, dtype=float)
            return np.broadcast_to(reference, self.q.shape) if reference.ndim == 1 else reference
        if self.reference is None:
            raise ValueError("this trace has no reference: give one (reference=[q1, q2] rad, "
                             "or one per row), or run the loop with reference=")
        return self.reference

    # -- rows --------------------------------------------------------------------------------

    def energy(self) -> dict:
        """The books by name (BOOKS), NaN where the trace has none (over the wire, a node
        that writes no recording)."""
        try:
            return {name: np.asarray(self.books[name]) for name in BOOKS}
        except KeyError:
            return {name: np.full(len(self), np.nan) for name in BOOKS}

    def rows(self) -> np.ndarray:
        """(N, len(COLUMNS)) in COLUMNS' order; NaN where the trace has no reference."""
        reference = self.reference if self.reference is not None else \
            np.full(self.q.shape, np.nan)
        b = self.energy()
        return np.column_stack([self.t, self.q, self.qd, self.measured_q, self.measured_qd,
                                self.command, self.tau, reference, b["kinetic"], b["stored"],
                                b["inputs"], b["losses"], b["residual"]])


def _figures(trace: Trace, q_ref: np.ndarray, band=None, after: float = 0.0,
             window: float | None = None) -> dict:
    """metrics.performance over the trace with a reference per row; a band of 2 % of the
    move, or the caller's (inf: a figure that does not need one)."""
    if band is None:
        move = np.abs(q_ref[0] - trace.q[0])
        if np.any(move == 0.0):
            raise ValueError("settle_time of a joint held where it starts needs band= (rad)")
        band = SETTLE_FRACTION * move
    figures = Performance(None, float(trace.t[-1]), band=band, after=after, window=window)
    figures.update(trace.t, trace.q, trace.tau, q_ref=q_ref)
    return figures.figures()
