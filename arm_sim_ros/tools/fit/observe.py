"""What a recording made with sensors shows of a simulated motion: the deterministic parts of
the sensor model (physics/sensing/sensors.py), in continuous time, so that a fit can move a
delay by less than a step.

At sample k (time t_k) the reading is q(t_k − delay) + position_offset and, as velocity,
q̇(t_k − delay) (velocity: true) or the difference of two such positions 1/rate apart over
1/rate (differences; 1/rate the scene's step without a rate). The motion between simulated
samples is the cubic Hermite interpolant of its positions and velocities there (error
~ dt⁴ |q⁗| / 384: 2e-10 rad at 2 ms and 1000 rad/s⁴), extrapolated before a segment's first
sample. Left out are the noise, which is what the residuals are weighed by, and the
quantisation: for a moving arm its round-off is noise of resolution / √12, zero on average,
and its staircase would leave least squares no gradient. `command_delay` shifts the commanded
torques: a command given at t acts from t + command_delay; over each sample interval the
torque held is its average there (the impulse exact and smooth in the delay).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

# The keys a fit can free that the sensors and the command latency hold.
SENSING_KEYS = ("sensors.delay", "sensors.position_offset", "command_delay")


@dataclass(frozen=True)
class Observation:
    """The deterministic sensor model of one scene, delays in seconds."""

    offset: tuple = (0.0, 0.0)
    delay: float = 0.0
    differences: bool = False
    period: float = 0.0              # s between the differenced positions (1/rate)
    command_delay: float = 0.0

    @classmethod
    def of(cls, scene) -> Observation:
        sensors = scene.sensors or {}
        rate = sensors.get("rate")
        return cls(tuple(sensors.get("position_offset", (0.0, 0.0))),
                   sensors.get("delay", 0.0), sensors.get("velocity") == "differences",
                   1.0 / rate if rate else scene.step_size, scene.command_delay)

    def with_values(self, free, values) -> Observation:
        """This model with the free sensing parameters (keys.FreeParameter) at `values`."""
        changes, offset = {}, list(self.offset)
        for p, v in zip(free, values):
            if p.field == "command_delay":
                changes["command_delay"] = float(v)
            elif p.name == "delay":
                changes["delay"] = float(v)
            elif p.name == "position_offset":
                for i in ((0, 1) if p.index is None else (p.index,)):
                    offset[i] = float(v)
        return replace(self, offset=tuple(offset), **changes)

    def readings(self, states, dt: float) -> np.ndarray:
        """(n, 4) readings of the (n, 4) states simulated at the samples, dt apart."""
        q, qd = motion_at(states, dt, self.delay)
        if self.differences:
            before, _ = motion_at(states, dt, self.delay + self.period)
            qd = (q - before) / self.period
        return np.hstack([q + np.asarray(self.offset), qd])

    def torques(self, tau, dt: float) -> np.ndarray:
        """The commanded torques (n, 2), held over their sample intervals, as they act."""
        return delayed(np.asarray(tau, dtype=float), self.command_delay / dt)


def motion_at(states, dt: float, shift: float):
    """(q, q̇) at each sample's time less `shift` s: the cubic Hermite interpolant of the
    states simulated at the samples."""
    states = np.asarray(states, dtype=float)
    n = len(states)
    u = np.arange(n) - shift / dt
    i = np.clip(np.floor(u).astype(int), 0, n - 2)
    s = (u - i)[:, None]
    q0, q1, v0, v1 = states[i, :2], states[i + 1, :2], states[i, 2:], states[i + 1, 2:]
    q = ((2 * s**3 - 3 * s**2 + 1) * q0 + (s**3 - 2 * s**2 + s) * dt * v0
         + (3 * s**2 - 2 * s**3) * q1 + (s**3 - s**2) * dt * v1)
    qd = ((6 * s**2 - 6 * s) * (q0 - q1) / dt + (3 * s**2 - 4 * s + 1) * v0
          + (3 * s**2 - 2 * s) * v1)
    return q, qd


def delayed(tau: np.ndarray, samples: float) -> np.ndarray:
    """tau (held over each sample interval) as it acts `samples` intervals later: over each
    interval the average of what acts there (the first command before the recording)."""
    if samples == 0.0:
        return tau
    whole, part = int(np.floor(samples)), samples - np.floor(samples)
    index = np.arange(len(tau)) - whole
    now, before = tau[np.clip(index, 0, None)], tau[np.clip(index - 1, 0, None)]
    return (1.0 - part) * now + part * before
