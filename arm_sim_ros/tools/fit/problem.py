"""The least-squares problem of `arm-sim fit`: simulated against measured trajectories.

Multiple shooting: each recording is cut into segments (SEGMENT_SECONDS); each segment is
simulated from a start state of its own, which is fitted together with the parameters and
tied to the measured state at the segment's first sample by that sample's residual. A long
or chaotic recording then never makes the cost meaningless (a segment is too short to
diverge), and the noise of one measured sample does not bias the segment as a restart from
it would. The last VALIDATION_FRACTION of each recording is held out.

The simulator replays the recorded torque held over each sample interval (as the node
holds a command), with the scene's own exact stick-slip friction and limits, at a fixed
step (tolerance 0: no adaptive sub-steps, so the trajectory is a smooth function of the
parameters between switches and finite differences are reproducible), and with no error
estimate (estimate off: no shadow, no checks, which a rollout would only pay for). Residuals are
(simulated - measured) / σ per channel, σ each channel's noise estimated from the data, at
least the replay's resolution (noise_level), so the cost is a χ² and ~1 per residual at the
noise level.

A recording made with sensors is compared through their deterministic parts (observe.py):
the simulated truth delayed, offset and differenced as the readings were, and the commands
shifted by command_delay; sensors.delay, sensors.position_offset and command_delay are then
free keys like the others, continuous (the replay itself has no sensors).

Scaling: parameter i is searched as x = value / scale_i (scale: its start value), a
segment's start state as its offset from the measured one in units of σ. The Jacobian is
by forward differences; a start state's columns are taken for every segment at once (the
segments are independent), so a Jacobian costs n_parameters + 4 simulations of the data.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ...physics.scene import SceneError
from ...physics.simulator import Simulator
from .bounds import MAX_STEPS_PER_SAMPLE, check_sampling
from .data import FitError
from .keys import start_values, with_values
from .observe import SENSING_KEYS, Observation

SEGMENT_SECONDS = 1.0
VALIDATION_FRACTION = 0.2
PARAMETER_STEP = 1e-6     # finite-difference step of a scaled parameter (relative)
STATE_STEP = 1e-4         # ... of a start state, in units of the channel's noise
NOISE_FLOOR = 1e-9        # rad, rad/s: the σ of a still, noiseless recording
# The replay holds each torque over its sample interval and moves a delay within one by
# interpolants (observe.py), so it reproduces a motion only to a share of what a channel
# changes over one interval: up to 2.2e-3 of it (RMS) measured with an exact velocity and
# a 1.5-sample command delay. Below this share a residual is the replay's, not the arm's.
REPLAY_RESOLUTION = 5e-3
FAILED = 1e6              # residual of a parameter set the scene refuses


def noise_level(recording) -> np.ndarray:
    """σ of q1, q2, qd1, qd2, by which residuals are weighed: the noise, the robust spread
    (median absolute deviation) of 4th differences, which remove a smooth signal and leave
    white noise x sqrt(70); but never below the replay's resolution, REPLAY_RESOLUTION of
    the channel's RMS change over a sample interval (an exact channel's noise is the
    replay's error, which 4th differences cannot see)."""
    x = np.hstack([recording.q, recording.qd])
    fourth = np.diff(x, n=4, axis=0)
    mad = np.median(np.abs(fourth - np.median(fourth, axis=0)), axis=0) if len(fourth) \
        else np.zeros(4)                   # too short for it: excite at a low --rate
    change = np.sqrt(np.mean(np.diff(x, axis=0) ** 2, axis=0)) if len(x) > 1 else np.zeros(4)
    return np.maximum.reduce([1.4826 * mad / np.sqrt(70.0), REPLAY_RESOLUTION * change,
                              np.full(4, NOISE_FLOOR)])


def replay_scene(base, mode: str, recording):
    """The scene that replays a recording's torque: the `effort` is what the joints received
    (no policy, limits or windings again); commands go through the scene's drive chain."""
    substeps, dt = check_sampling(recording, base.step_size), recording.dt
    changes = {"step_size": dt / substeps, "tolerance": 0.0, "estimate": "off",
               "sensors": None, "command_delay": 0.0,     # seen through them: observe.py
               "initial_positions": (0.0, 0.0), "initial_velocities": (0.0, 0.0)}
    if mode == "effort":
        changes |= {"policy": "command", "effort_limits": None, "controller_model": None}
        if base.motors is not None:     # the gears' inertia stays, the windings go
            changes["motors"] = {k: base.motors[k] for k in ("gear_ratio", "rotor_inertia")}
    elif not base.policy.startswith("command"):
        changes["policy"] = "command"
    return base.replace(**changes), substeps


@dataclass(frozen=True)
class Segment:
    recording: int
    start: int       # first sample
    stop: int        # one past the last


def cut(length: int, dt: float, seconds: float, recording: int) -> list[Segment]:
    """Samples [0, length) in segments of about `seconds` (the last one absorbs the rest)."""
    size = max(2, int(round(seconds / dt)))
    starts = list(range(0, max(1, length - size // 2), size))
    bounds = starts + [length]
    return [Segment(recording, a, b) for a, b in zip(bounds, bounds[1:]) if b - a >= 2]


class Problem:
    """Recordings, the base scene and its free parameters; simulation and residuals."""

    def __init__(self, base, free, recordings, mode: str = "effort",
                 segment_seconds: float = SEGMENT_SECONDS,
                 validation: float = VALIDATION_FRACTION):
        self.base, self.free, self.recordings, self.mode = base, list(free), list(recordings), mode
        self.sensing = [i for i, p in enumerate(self.free) if p.key.partition("[")[0]
                        in SENSING_KEYS]           # observed through the sensors (observe.py)
        self.physical = [i for i in range(len(self.free)) if i not in self.sensing]
        if mode == "effort" and any(self.free[i].field == "command_delay" for i in self.sensing):
            raise FitError("--free command_delay needs the commands (--torque-topic): the "
                           "JointState effort is the torque as it acts, already delayed")
        self.replays = [replay_scene(base, mode, r) for r in self.recordings]
        self.sigma = [noise_level(r) for r in self.recordings]
        self.scale = np.abs(np.array(start_values(self.free, base), dtype=float))
        self.lower = np.array([p.lower for p in self.free]) / self.scale
        self.training, self.validation = [], []
        for k, r in enumerate(self.recordings):
            held = int(round(validation * len(r)))
            held = held if held >= 10 else 0
            self.training += cut(len(r) - held, r.dt, segment_seconds, k)
            if held:
                self.validation.append(Segment(k, len(r) - held, len(r)))

    @property
    def n_parameters(self) -> int:
        return len(self.free)

    def values(self, xp) -> np.ndarray:
        return np.asarray(xp) * self.scale

    def measured(self, segment: Segment) -> np.ndarray:
        r = self.recordings[segment.recording]
        return np.hstack([r.q, r.qd])[segment.start:segment.stop]

    def scenes(self, xp):
        """The replay scene of each recording at scaled parameters xp (None: refused)."""
        values, free = self.values(xp), self.free
        try:
            return [(with_values(scene, [free[i] for i in self.physical], values[self.physical]),
                     n) for scene, n in self.replays]
        except SceneError:
            return None

    def observation(self, xp) -> Observation:
        """The sensors' deterministic parts at scaled parameters xp (observe.py)."""
        return Observation.of(self.base).with_values([self.free[i] for i in self.sensing],
                                                     self.values(xp)[self.sensing])

    def simulate(self, xp, states, segments) -> list[np.ndarray] | None:
        """(n, 4) q1, q2, qd1, qd2 of each segment from its scaled start state."""
        scenes, seen = self.scenes(xp), self.observation(xp)
        if scenes is None:
            return None
        sims, out, offset = {}, [], np.array([*seen.offset, 0.0, 0.0])
        torques = [seen.torques(r.tau, r.dt) for r in self.recordings]
        for segment, s in zip(segments, np.reshape(states, (-1, 4))):
            k = segment.recording
            scene, substeps = scenes[k]
            start = self.measured(segment)[0] - offset + self.sigma[k] * s
            sims[k] = sim = restarted(sims.get(k), scene, start)
            if sim.substeps * substeps > MAX_STEPS_PER_SAMPLE:   # refused: bounds.py
                return None
            run = rollout(sim, substeps, torques[k][segment.start:segment.stop])
            out.append(seen.readings(run, self.recordings[k].dt) if self.observed else run)
        return out

    @property
    def observed(self) -> bool:
        """Whether the recording is compared through sensors (the base's, or free keys)."""
        return bool(self.sensing) or self.base.sensors is not None

    def residuals(self, xp, states, segments) -> list[np.ndarray]:
        """Per segment, the flattened (simulated - measured) / σ."""
        runs = self.simulate(xp, states, segments)
        if runs is None:
            return [np.full(4 * (g.stop - g.start), FAILED) for g in segments]
        return [((run - self.measured(g)) / self.sigma[g.recording]).ravel()
                for run, g in zip(runs, segments)]

    def jacobian(self, xp, states, segments, r0, with_parameters: bool = True) -> np.ndarray:
        """d residuals / d (xp, states) by forward differences; the states' columns of all
        segments from one simulation per state component."""
        sizes = [4 * (g.stop - g.start) for g in segments]
        rows = np.cumsum([0] + sizes)
        first = self.n_parameters if with_parameters else 0
        jac = np.zeros((rows[-1], first + 4 * len(segments)))
        r0 = np.concatenate(r0)
        for i in range(first):
            h = PARAMETER_STEP * max(1.0, abs(xp[i]))
            shifted = np.array(xp, dtype=float)
            shifted[i] += h
            jac[:, i] = (np.concatenate(self.residuals(shifted, states, segments)) - r0) / h
        for c in range(4):
            shifted = np.array(states, dtype=float)
            shifted[c::4] += STATE_STEP
            blocks = self.residuals(xp, shifted, segments)
            for j, block in enumerate(blocks):
                a, b = rows[j], rows[j + 1]
                jac[a:b, first + 4 * j + c] = (block - r0[a:b]) / STATE_STEP
        return jac


def restarted(sim, scene, start) -> Simulator:
    """A simulator of `scene` reset to `start`: `sim` again where it has the same dynamics
    (its compiled modes are kept: a third of the cost of a short segment), else a new one."""
    scene = scene.replace(initial_positions=(float(start[0]), float(start[1])),
                          initial_velocities=(float(start[2]), float(start[3])))
    if sim is not None:
        sim.scene = scene
        sim.reset()
        if sim.state[:4] == tuple(scene.initial_positions + scene.initial_velocities):
            return sim
    return Simulator(scene)


def rollout(sim, substeps: int, tau) -> np.ndarray:
    """`sim` from its state, tau[k] held over sample interval k: the state at each sample
    (the first is where it starts)."""
    out = [sim.state[:4]]
    step, command = sim.step, sim.set_command
    for t1, t2 in tau[:-1].tolist():
        command(t1, t2)
        for _ in range(substeps):
            step()
        out.append(sim.state[:4])
    return np.array(out)


def starts(n: int, count: int, seed: int = 0) -> list[np.ndarray]:
    """Scaled start points: the base scene's values, then `count` - 1 spread log-uniformly
    from a third to three times them (seeded: every run tries the same)."""
    rng = np.random.default_rng(seed)
    spread = np.exp(rng.uniform(np.log(1 / 3), np.log(3), size=(max(0, count - 1), n)))
    return [np.ones(n)] + list(spread)


class OutOfTime(Exception):
    """The wall-time bound passed within an evaluation."""


def solve(problem: Problem, xp0, segments, max_nfev: int | None = None,
          with_parameters: bool = True, states0=None, deadline: float | None = None) -> dict:
    """least_squares from scaled parameters xp0 (fixed unless `with_parameters`) and
    measured start states: the scaled x, cost per iteration, status and message. Past
    `deadline` (time.time()) it stops with the best point it evaluated (status -3)."""
    from scipy.optimize import least_squares

    n = problem.n_parameters if with_parameters else 0
    xp0 = np.asarray(xp0, dtype=float)
    states0 = np.zeros(4 * len(segments)) if states0 is None else states0
    split = (lambda x: (x[:n], x[n:])) if with_parameters else (lambda x: (xp0, x))
    cache, history, best = {}, [], {}

    def fun(x):
        if deadline is not None and time.time() > deadline and best:
            raise OutOfTime
        xp, states = split(x)
        cache["x"], cache["r"] = x.copy(), problem.residuals(xp, states, segments)
        r = np.concatenate(cache["r"])
        if not history:                     # the cost at the start
            history.append(0.5 * float(r @ r))
        if not best or 0.5 * float(r @ r) < best["cost"]:
            best.update(x=x.copy(), cost=0.5 * float(r @ r), fun=r)
        return r

    def jac(x):
        if deadline is not None and time.time() > deadline:
            raise OutOfTime             # a Jacobian costs n + 4 simulations: not begun
        if "x" not in cache or not np.array_equal(cache["x"], x):
            fun(x)
        return problem.jacobian(*split(x), segments, cache["r"], with_parameters)

    x0 = np.concatenate([xp0, states0]) if with_parameters else states0
    lower = np.concatenate([problem.lower, np.full(len(states0), -np.inf)]) if with_parameters \
        else -np.inf
    def callback(intermediate_result):
        history.append(float(intermediate_result.cost))
        if deadline is not None and time.time() > deadline:
            raise StopIteration

    try:
        result = least_squares(fun, x0, jac=jac, bounds=(lower, np.inf), method="trf",
                               tr_solver="exact", max_nfev=max_nfev, x_scale=1.0,
                               callback=callback)
        x, cost, status, message = result.x, float(result.cost), int(result.status), str(
            result.message)
        nfev, residuals = int(result.nfev), len(result.fun)
    except OutOfTime:
        result = None
    if result is None or status == -2:      # the wall-time bound: the best point seen
        x, cost, status, message = best["x"], best["cost"], -3, "wall-time bound reached"
        nfev, residuals = len(history), len(best["fun"])
    xp, states = split(x)
    return {"xp": np.array(xp), "states": np.array(states), "cost": cost,
            "history": history, "status": status, "message": message,
            "nfev": nfev, "residuals": residuals}


def fit_from(problem: Problem, xp0, max_nfev: int | None = None,
             deadline: float | None = None) -> dict:
    """One start of a multi-start fit (a task for a process pool or a Dask worker)."""
    return solve(problem, xp0, problem.training, max_nfev, deadline=deadline)
