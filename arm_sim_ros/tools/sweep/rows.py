"""One block of a sweep: its samples' scenes built, run together (physics/batch.py
run_scenes: samples of one structure in compiled calls), and their rows made.

A row: the sample's index, its varied keys' values, its outcome (ok, diverged, refused,
fault), final state, steps and sub-steps, the largest |residual| of the energy balance, the
error estimate (NaN when off), the controller's figures (physics/metrics.py, per joint:
`_1`, `_2`) and the reason of an outcome that is not ok. Figures need a reference: a
position servo's set-point (policy setpoint); elsewhere they are NaN, but for peak_torque,
which needs none. A row that is not ok has no figures: the run they would describe ended.
A scene the sample's values make impossible is a refused row, never a failed sweep.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from math import nan

import numpy as np

from ...physics.compiled.cache import compile_seconds
from ...physics.metrics import NAMES, SETTLE_FRACTION, Performance
from ...physics.scene import Scene, SceneError
from .plan import Plan

OUTCOMES = ("ok", "diverged", "refused", "fault")
STATE = ("q_1", "q_2", "qd_1", "qd_2")
BOOKS = ("steps", "substeps", "max_abs_residual", "accumulated_error")
NO_REFERENCE = ("peak_torque",)         # figures that need no reference


def figure_columns(metrics) -> tuple:
    return tuple(f"{name}_{joint}" for name in metrics for joint in (1, 2))


def header(plan: Plan, metrics) -> tuple:
    return ("index", *plan.columns, "status", *STATE, *BOOKS, *figure_columns(metrics),
            "reason")


@dataclass(frozen=True)
class Task:
    """What a worker needs to run samples first..stop-1: everything a row depends on."""

    base: Scene
    plan: Plan
    duration: float
    metrics: tuple
    after: float
    first: int
    stop: int


@dataclass
class Done:
    """A block's rows (tuples of Python values, in index order), its wall seconds and the
    seconds of them its worker spent compiling kernels."""

    first: int
    stop: int
    rows: list
    seconds: float
    compiling: float


def reference(scene: Scene):
    """(q_ref (2,), which joints have one (2,), which of those hold their initial position
    (2,)): a position servo's set-point. A hold has no 2 % band: no settle_time."""
    servo = scene.servo or {}
    interfaces = servo.get("interface", ("position", "position"))
    has = np.array([scene.policy == "setpoint" and i == "position" for i in interfaces])
    ref = np.array(scene.setpoint, dtype=float)
    return ref, has, has & (ref == np.array(scene.initial_positions))


class Figures:
    """The controller's figures of every sample, fed the observe chunks: one Performance
    per group of rows run_scenes runs together (the same `indices` each chunk)."""

    def __init__(self, scenes, duration: float, after: float, halted=None):
        self.scenes, self.duration, self.after = scenes, duration, after
        self.halted = halted          # raises when the sweep stops (pool.py)
        self.groups: dict = {}

    def observe(self, indices, t, q, qd, tau) -> None:
        if self.halted is not None:
            self.halted()
        key = tuple(int(i) for i in indices)
        if key not in self.groups:
            self.groups[key] = self._performance(key)
        self.groups[key].update(t, q, tau)

    def _performance(self, key) -> Performance:
        refs, start = [], []
        for i in key:
            ref, has, _ = reference(self.scenes[i])
            initial = np.array(self.scenes[i].initial_positions)
            refs.append(np.where(has, ref, initial + 1.0))     # (blanked after: no reference)
            start.append(initial)
        refs, distance = np.array(refs), np.abs(np.array(refs) - np.array(start))
        band = np.where(distance > 0, SETTLE_FRACTION * distance, 1.0)   # a hold: none
        return Performance(refs, self.duration, band=band, after=self.after)

    def of(self) -> dict:
        """{sample position: {name: (2,) array}} of every sample observed."""
        found = {}
        for key, performance in self.groups.items():
            figures = performance.figures()
            for row, i in enumerate(key):
                found[i] = {name: np.array(values[row], dtype=float)
                            for name, values in figures.items()}
        return found


def run_task(task: Task, halted=None) -> Done:
    """The block's rows; a sample that cannot run is a row saying why, never an exception.
    `halted()` raises when the sweep stops (looked at with every chunk of samples)."""
    from ...physics.batch import run_scenes       # the engine: imported with the work

    started, compiled = time.perf_counter(), compile_seconds()
    values = [task.plan.values(index) for index in range(task.first, task.stop)]
    scenes, refused = [], {}
    for k, at in enumerate(values):
        try:
            scene = task.plan.scene(task.base, at)
            scene.steps_for(task.duration)
            scenes.append((k, scene))
        except SceneError as error:
            refused[k] = str(error)
    runnable = [scene for _, scene in scenes]
    figures = Figures(runnable, task.duration, task.after, halted)
    outcomes = run_scenes(runnable, task.duration, observe=figures.observe) if runnable else []
    measured = figures.of()
    by_row = {k: (outcome, measured.get(n), scene)
              for n, ((k, scene), outcome) in enumerate(zip(scenes, outcomes))}
    rows = []
    for k, at in enumerate(values):
        cells = (task.first + k, *task.plan.cells(at))
        if k in refused:
            rows.append(cells + refused_row(refused[k], task.metrics))
        else:
            rows.append(cells + outcome_row(*by_row[k], task.metrics))
    return Done(task.first, task.stop, rows, time.perf_counter() - started,
                compile_seconds() - compiled)


def refused_row(reason: str, metrics) -> tuple:
    return ("refused", *(nan,) * len(STATE), 0, 0, nan, nan,
            *(nan,) * len(figure_columns(metrics)), reason)


def outcome_row(outcome, figures, scene: Scene, metrics) -> tuple:
    ok = outcome.status == "ok"
    _, has, hold = reference(scene)
    cells = []
    for name in metrics:
        value = figures[name] if ok and figures is not None else np.full(2, nan)
        shown = value if name in NO_REFERENCE else np.where(has, value, nan)
        shown = np.where(hold, nan, shown) if name == "settle_time" else shown
        cells += [float(v) for v in shown]
    return (outcome.status, *(float(v) for v in outcome.q), *(float(v) for v in outcome.qd),
            int(outcome.steps), int(outcome.substeps), float(outcome.max_abs_residual),
            float(outcome.accumulated_error), *cells, outcome.reason)


def check_metrics(text: str | None) -> tuple:
    """--metrics NAME[,NAME...] (default: every figure) as names, or SceneError."""
    if text is None:
        return NAMES
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    unknown = [n for n in names if n not in NAMES]
    if unknown or not names:
        from ...usage import did_you_mean
        hint = did_you_mean(unknown[0], NAMES) if unknown else ""
        raise SceneError(f"--metrics {text}: {unknown[0] if unknown else 'none'} is no "
                         f"figure; {hint}figures: {', '.join(NAMES)}")
    return tuple(n for n in NAMES if n in names)

