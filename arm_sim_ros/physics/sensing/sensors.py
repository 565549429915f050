"""The sensors a scene calls for: what is published and what the drive reads, in place of
the exact state.

Scene (every key optional; every key absent is the exact state, at no cost):

    sensors:
      seed: 7                  # every draw comes from this seed; same seed, same numbers
      rate: 500.0              # Hz; sampled at this rate, held in between (default: every
                               # step); 1/rate a whole number of steps
      position_resolution: [0.0015339807878856412, 0.0015339807878856412]  # rad per count
      position_noise: [1.0e-4, 1.0e-4]    # rad, Gaussian standard deviation, per sample
      position_offset: [0.0, 0.0]         # rad, calibration error of the zero
      velocity: differences    # or `true`: the true velocity plus velocity_noise
      velocity_noise: [1.0e-3, 1.0e-3]    # rad/s, with velocity: true
      delay: 0.002             # s, a reading published at t is the measurement at t - delay

Sample k, taken at t_k = k/rate from t = 0 (a live rate change: 1/rate after the latest
sample), measures joint i at the state (q, q̇) there as

    p_k = quantise(q + offset + σ n),  quantise(x) = round(x / r) × r   (half to even)
    v_k = (p_k − p_k−1) / (1/rate)      (differences; 0 at sample 0, which has none before)
    v_k = q̇ + σ_v n'                     (true)

with n, n' standard normal draws of (seed, joint, k) (noise.py). The delay and the
whole-number rules are checked here against the step size, in the scene's words.
"""
from __future__ import annotations

from math import isfinite

from ..effects.base import Parameter
from ..model import MAX_ANGLE, ParameterError
from .noise import POSITION, VELOCITY, Draws

VELOCITIES = ("differences", "true")
RELATIVE = 1e-9           # how close to a whole number of steps a period must come


class Sensors:
    """The scene key `sensors`: its parameters and their cross-checks."""

    name = "sensors"
    parameters = (
        Parameter("seed", "int", "1", "whole", default=0,
                  description="seed of every draw: the same seed gives the same readings"),
        Parameter("rate", "float", "Hz", "positive", default=None,
                  description="sample rate, readings held in between; 1/rate a whole number "
                              "of steps (none = every step)"),
        # A reading is an angle: its resolution, noise and offset are angles too, within the
        # largest angle a state may hold, so that every reading and every difference of two
        # over a period stays a double (a noise of 1e306 rad read inf).
        Parameter("position_resolution", "pair", "rad per count", "positive", default=None,
                  description="encoder resolution: readings are whole counts of it "
                              "(none = not quantised)", limit=MAX_ANGLE),
        Parameter("position_noise", "pair", "rad", "non-negative", default=(0.0, 0.0),
                  description="standard deviation of the Gaussian noise on each position "
                              "sample", limit=MAX_ANGLE),
        Parameter("position_offset", "pair", "rad", default=(0.0, 0.0),
                  description="calibration error of each encoder's zero, added to the reading",
                  limit=MAX_ANGLE),
        Parameter("velocity", "choice", "differences|true", default="true",
                  choices=VELOCITIES,
                  description="velocity read as the difference of the last two position "
                              "samples over 1/rate, or the true velocity plus velocity_noise"),
        Parameter("velocity_noise", "pair", "rad/s", "non-negative", default=(0.0, 0.0),
                  description="standard deviation of the Gaussian noise on each velocity "
                              "sample (velocity: true)", limit=MAX_ANGLE),
        Parameter("delay", "float", "s", "non-negative", default=0.0,
                  description="a reading published at t is the measurement taken at t - delay; "
                              "a whole number of steps"),
    )

    def __init__(self, seed=0, rate=None, position_resolution=None,
                 position_noise=(0.0, 0.0), position_offset=(0.0, 0.0), velocity="true",
                 velocity_noise=(0.0, 0.0), delay=0.0):
        if velocity == "differences" and any(velocity_noise):
            raise ParameterError("sensors.velocity_noise is for velocity: true; differenced "
                                 "velocities take their noise from the positions")
        self.seed, self.rate, self.resolution = seed, rate, position_resolution
        self.noise, self.offset, self.velocity = position_noise, position_offset, velocity
        self.velocity_noise, self.delay = velocity_noise, delay


def whole_steps(seconds: float, step_size: float) -> int | None:
    """`seconds` as a whole number of steps, None if it is not one (or more steps than a
    double counts: a rate of 1e-310 Hz, a delay of 1e308 s)."""
    if not isfinite(seconds / step_size):
        return None
    steps = round(seconds / step_size)
    return steps if abs(steps * step_size - seconds) <= RELATIVE * max(seconds,
                                                                        step_size) else None


def delay_steps(name: str, seconds: float, step_size: float) -> int:
    """A delay (sensors.delay, command_delay) in whole steps, or one line refusing it."""
    if not seconds >= 0:
        raise ParameterError(f"{name} = {seconds:g} s must be >= 0 (s; 0 = none)")
    steps = whole_steps(seconds, step_size)
    if steps is None:
        raise ParameterError(f"{name} = {seconds:g} s is {seconds / step_size:.6g} steps of "
                             f"{step_size:g} s; a delay must be a whole number of steps")
    return steps


def quantise(x: float, resolution: float) -> float:
    """x as a whole number of counts of `resolution` (half to even). A resolution so fine
    that the count is beyond the doubles (1e-310 rad) is finer than x's own rounding: x is
    then a whole count already, as exactly as a double can say."""
    counts = x / resolution
    return round(counts) * resolution if isfinite(counts) else x


class SensorModel:
    """A scene's sensors at its step size: what each sample measures. `exact`: nothing is
    modelled (the readings are the state itself)."""

    def __init__(self, values: dict | None, step_size: float):
        sensors = Sensors(**(values or {}))
        self.step_size, self.velocity = step_size, sensors.velocity
        self.resolution, self.noise, self.offset = (sensors.resolution, sensors.noise,
                                                    sensors.offset)
        self.velocity_noise = sensors.velocity_noise
        self.every, self.period = 1, step_size
        if sensors.rate is not None:
            self.every = whole_steps(1.0 / sensors.rate, step_size) or 0
            if self.every < 1:
                raise ParameterError(
                    f"sensors.rate = {sensors.rate:g} Hz samples every "
                    f"{1.0 / sensors.rate / step_size:.6g} steps of {step_size:g} s; 1/rate "
                    "must be a whole number of steps")
            self.period = 1.0 / sensors.rate
        self.delay = delay_steps("sensors.delay", sensors.delay, step_size)
        self.draws = Draws(sensors.seed)
        self.exact = (self.every == 1 and self.resolution is None and not any(self.noise)
                      and not any(self.offset) and self.velocity == "true"
                      and not any(self.velocity_noise) and self.delay == 0)

    def positions(self, q, index: int) -> list:
        """quantise(q + offset + σ n) of both joints at sample `index`."""
        out = []
        for j in (0, 1):
            x = q[j] + self.offset[j]
            if self.noise[j]:
                x += self.noise[j] * self.draws.normal(POSITION, j, index)
            if self.resolution is not None:
                x = quantise(x, self.resolution[j])
            out.append(x)
        return out

    def velocities(self, qd, index: int, positions, previous, interval: float) -> list:
        """Both joints' measured velocities at sample `index`: the difference of `positions`
        and the `previous` sample's over `interval` (s; none before: 0), or q̇ + σ_v n'."""
        if self.velocity == "differences":
            if previous is None:
                return [0.0, 0.0]
            return [(p - b) / interval for p, b in zip(positions, previous)]
        return [v + s * self.draws.normal(VELOCITY, j, index) if s else v
                for j, (v, s) in enumerate(zip(qd, self.velocity_noise))]
