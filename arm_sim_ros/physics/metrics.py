"""How a controller did, from its trace: the one definition of each figure a controller's
author asserts on (arm_sim_ros.testing) and a sweep tabulates (tools/sweep).

A trace is fed in chunks, in time order: times t of shape (K,), positions q and joint
torques tau of shape (..., K, 2) (leading axes: many samples at once, as a sweep has them),
and the reference q_ref: a constant of shape (..., 2) given up front, or one per time,
shaped as q, given with each chunk. Every figure is per joint, shape (..., 2):

- peak_torque: the largest |tau|, N m.
- overshoot: how far q went past the reference, rad, in the direction it set out from its
  initial position towards it (0 if it never passed); for a reference at the initial
  position (a hold), the largest |q - q_ref| either way.
- settle_time: the first time from which |q - q_ref| stays within `band` to the end; NaN if
  the trace ends outside it. `band` is rad, per joint; by default 2 % of the initial
  distance to the reference (the common 2 % criterion); a hold must be given one.
- tracking_error: the root mean square of q - q_ref over t >= `after`, rad.
- steady_state_error: the mean |q - q_ref| over the trace's last `window` seconds (by
  default its last tenth), rad; `end`, the trace's last time, is given up front.
"""
from __future__ import annotations

import numpy as np

SETTLE_FRACTION = 0.02      # the 2 % criterion
STEADY_FRACTION = 0.1       # the last tenth of a trace is its steady state
NAMES = ("peak_torque", "overshoot", "settle_time", "tracking_error", "steady_state_error")


class Performance:
    """The figures above, accumulated chunk by chunk (`update`); `figures()` gives them."""

    def __init__(self, q_ref, end: float, *, band=None, after: float = 0.0,
                 window: float | None = None):
        self.q_ref = None if q_ref is None else np.asarray(q_ref, dtype=float)
        self.band = None if band is None else np.asarray(band, dtype=float)
        self.after = after
        self.steady_from = end - (STEADY_FRACTION * end if window is None else window)
        self.times: list = []              # every chunk's times: settle_time reads them
        self.count = 0                     # samples seen
        self.peak = self.over = self.outside = None
        self.squares = self.steady_sum = 0.0
        self.tracked = self.steady_count = 0

    def update(self, t, q, tau, q_ref=None) -> None:
        t, q, tau = np.asarray(t, dtype=float), np.asarray(q, dtype=float), np.asarray(tau)
        ref = self.q_ref if q_ref is None else np.asarray(q_ref, dtype=float)
        if ref.ndim == q.ndim - 1:                       # a constant: the same at every time
            ref = np.expand_dims(ref, -2)
        error = q - ref
        if self.peak is None:
            self._begin(q[..., 0, :], np.broadcast_to(ref, q.shape)[..., 0, :])
        self.peak = np.maximum(self.peak, np.abs(tau).max(axis=-2))
        past = np.where(np.expand_dims(self.holding, -2), np.abs(error),
                        error * np.expand_dims(self.direction, -2))
        self.over = np.maximum(self.over, past.max(axis=-2))
        index = self.count + np.arange(len(t))[:, None]      # (K, 1): each sample's index
        outside = np.abs(error) > np.expand_dims(self.band, -2)
        self.outside = np.maximum(self.outside, np.where(outside, index, -1).max(axis=-2))
        tracked = t >= self.after
        self.squares = self.squares + (error[..., tracked, :] ** 2).sum(axis=-2)
        self.tracked += int(tracked.sum())
        steady = t >= self.steady_from - 1e-9 * max(1.0, abs(self.steady_from))
        self.steady_sum = self.steady_sum + np.abs(error[..., steady, :]).sum(axis=-2)
        self.steady_count += int(steady.sum())
        self.times.append(t)
        self.count += len(t)

    def _begin(self, first, target) -> None:
        distance = target - first
        self.holding = distance == 0.0
        self.direction = np.sign(distance)
        if self.band is None:
            if np.any(self.holding):
                raise ValueError("settle_time of a hold (the reference at the initial "
                                 "position) needs a band, in rad")
            self.band = SETTLE_FRACTION * np.abs(distance)
        self.band = np.broadcast_to(self.band, distance.shape)
        self.peak = np.zeros(distance.shape)
        self.over = np.zeros(distance.shape)
        self.outside = np.full(distance.shape, -1)       # the latest index outside the band

    def figures(self) -> dict:
        """{name: array (..., 2)} for every name in NAMES."""
        if self.peak is None:
            raise ValueError("no samples: a trace needs at least one time")
        times = np.concatenate(self.times)
        settle_index = self.outside + 1                   # the sample after the latest outside
        ended_outside = settle_index >= len(times)
        settle = np.where(ended_outside, np.nan,
                          times[np.minimum(settle_index, len(times) - 1)])
        with np.errstate(invalid="ignore", divide="ignore"):
            tracking = np.sqrt(self.squares / self.tracked) if self.tracked else \
                np.full(self.peak.shape, np.nan)
            steady = self.steady_sum / self.steady_count if self.steady_count else \
                np.full(self.peak.shape, np.nan)
        return {"peak_torque": self.peak, "overshoot": self.over, "settle_time": settle,
                "tracking_error": np.broadcast_to(tracking, self.peak.shape),
                "steady_state_error": np.broadcast_to(steady, self.peak.shape)}


def performance(t, q, tau, q_ref, **options) -> dict:
    """The figures of one whole trace (arrays as Performance.update takes them)."""
    t = np.asarray(t, dtype=float)
    figures = Performance(q_ref, float(t[-1]), **options)
    figures.update(t, q, tau)
    return figures.figures()
