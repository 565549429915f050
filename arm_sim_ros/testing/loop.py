"""A controller under test, in process: a Python callable against a scene, at its own rate,
through the scene's sensors and command_delay, stepped by the simulator itself (its
compiled path where numba is installed). Deterministic: the same callable and scene give
the same trace, bit for bit, on any machine load.

    trace = closed_loop(pd, "release", seconds=3.0, rate=1000.0, reference=[0.5, -0.3])

The controller is called at t = 0 and every 1/rate s after (a whole number of steps; by
default every step) with a Reading: t, and q and qd as the drive reads them (numpy arrays
of two). It returns two numbers: joint torques in N m (command="torque", the default), or a
servo's set-points (command="position" or "velocity": the scene's `servo` takes them). What
it returns is held until its next call and acts command_delay later, as on the node.
"""
from __future__ import annotations

from collections import namedtuple
from math import isfinite

import numpy as np

from ..physics.scene import Scene, SceneError, load_scene
from ..physics.simulator import Simulator, recorded_row
from .trace import Trace

Reading = namedtuple("Reading", "t q qd")
COMMANDS = ("torque", "position", "velocity")
TORQUE_POLICIES = ("command", "command_gravity_compensation")


class ControllerError(Exception):
    """The controller returned something the arm cannot take; `trace` holds the run to
    that point (the test's evidence shows it)."""

    def __init__(self, message: str, trace: Trace | None = None):
        super().__init__(message)
        self.trace = trace


def scene_for(scene, overrides=None, command: str = "torque") -> Scene:
    """The Scene to run: a preset name or .yaml path (or a Scene), with `overrides` applied
    as `--set` applies them ({key: value}, or ["key=value", ...]); a torque-commanded loop
    gets policy command where the scene's policy follows none. The error estimate is off
    unless the overrides name `estimate` or `tolerance`: a controller's test asks how the
    controller does, and pays nothing for how accurate the integration is."""
    if command not in COMMANDS:
        raise ValueError(f"command must be one of {', '.join(COMMANDS)}, got {command!r}")
    base = scene if isinstance(scene, Scene) else load_scene(str(scene))
    if isinstance(overrides, dict):
        overrides = [f"{key}={_text(value)}" for key, value in overrides.items()]
    overrides = list(overrides or ())
    if not any(text.partition("=")[0].strip() in ("estimate", "tolerance") for text in overrides):
        base = base.replace(estimate="off")   # a controller's test, not the integration's
    base = base.with_text_overrides(overrides)
    if command == "torque" and base.policy not in TORQUE_POLICIES:
        base = base.replace(policy="command")
    return base


def _text(value) -> str:
    if isinstance(value, (list, tuple, np.ndarray)):
        return ",".join(repr(float(v)) if not isinstance(v, str) else v for v in value)
    return str(value)


def closed_loop(controller, scene="release", seconds: float = 1.0, *, rate: float | None = None,
                command: str = "torque", reference=None, overrides=None, recorder=None) -> Trace:
    """Run `controller` against `scene` for `seconds` (whole steps); the Trace of every step.
    `reference` ([q1, q2] rad, or a function of t giving them): what the trace's figures
    measure against, passed to nothing else. `recorder`: a Rerun recorder (recording/rrd)
    that hears every step, for the evidence of a failing test."""
    sim = Simulator(scene_for(scene, overrides, command))
    every = _every(rate, sim.step_size)
    steps = sim.scene.steps_for(seconds, sim.step_size)
    loop = _Loop(sim, controller, command, reference)
    if recorder is not None:
        recorder.start(sim)
    try:
        for k in range(steps):
            if k % every == 0:
                loop.ask()
            sim.step()
            loop.record()
            if recorder is not None:
                recorder.step(sim)
    except ControllerError as error:
        error.trace = loop.trace()
        raise
    finally:
        if recorder is not None:
            recorder.finish(sim)
    if steps % every == 0:            # the last state is due an answer it has not had
        loop.commands[-1] = (float("nan"), float("nan"))
    return loop.trace()


def _every(rate: float | None, step_size: float) -> int:
    """Steps between two calls of the controller: 1/rate, a whole number of steps."""
    if rate is None:
        return 1
    if not (isfinite(rate) and rate > 0):
        raise SceneError(f"rate must be a positive number of Hz, got {rate!r}")
    every = round(1.0 / (rate * step_size))
    if every < 1 or abs(every * rate * step_size - 1.0) > 1e-9:
        raise SceneError(f"rate {rate:g} Hz is not a whole number of steps of "
                         f"{step_size:g} s: choose 1/(k x {step_size:g} s)")
    return every


class _Loop:
    """The controller's side of a run, and the rows it leaves."""

    def __init__(self, sim: Simulator, controller, command: str, reference):
        self.sim, self.controller, self.command_kind = sim, controller, command
        self.reference = reference
        self.given = (0.0, 0.0)
        self.rows, self.commands, self.torques = [], [], []
        self.record()

    def ask(self) -> None:
        sim = self.sim
        r = sim.readings
        out = self.controller(Reading(sim.time, np.array(r[0:2]), np.array(r[2:4])))
        given = command_pair(out, sim.time, self.command_kind)
        if self.command_kind == "torque":
            sim.set_command(*given)
        else:
            field = self.command_kind
            sim.set_command(*sim.dynamics.given, {(field, 0): given[0], (field, 1): given[1]})
        self.given = self.commands[-1] = given     # the row it answered: held from there

    def record(self) -> None:
        """A row: the state, what was read there, the command held (until the controller
        answers it) and the torque the joints receive there under the command before."""
        self.rows.append(recorded_row(self.sim))
        self.commands.append(self.given)
        self.torques.append(self.sim.joint_torque())

    def trace(self) -> Trace:
        sim, rows = self.sim, self.rows
        states = [row[:len(sim.state_names)] for row in rows]
        array = np.array([row[:4] for row in rows])
        measured = np.array([row[len(sim.state_names):len(sim.state_names) + 4]
                             for row in rows]) if sim.scene.sensors is not None else array
        t = np.arange(len(rows)) * sim.step_size
        return Trace(t=t, q=array[:, 0:2], qd=array[:, 2:4], measured_q=measured[:, 0:2],
                     measured_qd=measured[:, 2:4], command=np.array(self.commands),
                     tau=np.array(self.torques), books=Books(sim, states),
                     reference=_reference(self.reference, t), scene=sim.scene.name)


def command_pair(out, t: float, kind: str) -> tuple:
    """The two finite numbers a controller answered, or ControllerError saying why not."""
    unit = "N m" if kind == "torque" else "rad" if kind == "position" else "rad/s"
    try:
        values = tuple(float(v) for v in out)
    except (TypeError, ValueError):
        raise ControllerError(f"the controller returned {out!r} at t = {t:.6f} s: expected "
                              f"two {kind}s in {unit}") from None
    if len(values) != 2 or not all(isfinite(v) for v in values):
        raise ControllerError(f"the controller returned {list(values)} at t = {t:.6f} s: "
                              f"expected two finite {kind}s in {unit}")
    return values


def _reference(reference, t: np.ndarray):
    if reference is None:
        return None
    if callable(reference):
        return np.array([tuple(reference(tk)) for tk in t], dtype=float)
    return np.broadcast_to(np.asarray(reference, dtype=float), (len(t), 2)).copy()


class Books(dict):
    """The energy books of the states, worked out when first read (a test that asserts
    on the motion alone pays nothing for them): kinetic, stored, inputs, losses, residual."""

    def __init__(self, sim: Simulator, states: list):
        super().__init__()
        self.sim, self.states = sim, states

    def __missing__(self, key):
        if not self.states:
            raise KeyError(key)
        sim = self.sim
        energies = np.array([sim.energies(state) for state in self.states])
        inputs_losses = np.array([sim.books(state) for state in self.states])
        self.update(kinetic=energies[:, 0], stored=energies[:, 1], inputs=inputs_losses[:, 0],
                    losses=inputs_losses[:, 1])
        self["residual"] = (energies.sum(axis=1) - sim.initial_energy - self["inputs"]
                            + self["losses"])
        self.states = []
        return self[key]
