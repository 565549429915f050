"""One scene through its own Simulator: the reference every batched rollout equals, and the
way a scene that cannot batch runs."""
from __future__ import annotations

import numpy as np

from ..compiled import runs
from ..effects.servo import servo_of
from ..simulator import Simulator
from .outcomes import FirstFault, Outcome, one_line, outcome_of, refused

BUILD_ERRORS = (ValueError, ArithmeticError)   # a scene or value refused: its one line
ROW = 6                   # a trajectory's row: q1, q2, q̇1, q̇2, τ1, τ2


class Built:
    """A scene's Simulator ready to run: the steps its duration takes, its first fault (an
    event listener), the row at t = 0 and the largest |residual| so far."""

    def __init__(self, index: int, sim, steps: int):
        self.index, self.sim, self.steps = index, sim, steps
        self.first = FirstFault()
        sim.event_listeners.append(self.first)
        self.start = row(sim)
        self.largest, self.error = 0.0, None

    def outcome(self) -> Outcome:
        return outcome_of(self.sim, self.largest, self.first, self.error)


def built(index: int, scene, duration: float):
    """The scene's Built, or the refused Outcome (its simulator cannot be built, or the
    duration is not a whole number of its steps)."""
    try:
        sim = Simulator(scene)
        compiled_servo(sim)
        return Built(index, sim, scene.steps_for(duration, sim.step_size))
    except BUILD_ERRORS as error:
        return refused(one_line(error, named=False))


def compiled_servo(sim) -> None:
    """A continuous servo's smooth scene runs compiled here too, its set-points read from K
    (the node keeps it in Python: a live switch of interface would meet a first compile;
    a rollout switches none)."""
    if sim.kernel is None and sim.switching is None and servo_of(sim.dynamics) is not None:
        sim.kernel = runs.kernel_for(sim.dynamics, sim._step, sim._driver, sim.sensing,
                                     servo=True)


def row(sim) -> tuple:
    """The trajectory's row now (as the compiled runs' recorded() writes it)."""
    return (*sim.state[:4], *sim.joint_torque())


def advance(sim, left: int, largest: float, rows=None) -> float:
    """Simulator.run's loop for `left` steps (the compiled kernel's runs, what it hands back
    taken in Python), each step's row into `rows` where given; the largest |residual|."""
    kernel, taken = sim.kernel, 0
    try:
        while taken < left:
            if rows is not None:
                kernel.T = rows[taken:]
            done, largest = kernel.run(sim, left - taken, largest)
            taken += done
    finally:
        kernel.T = rows[:0] if rows is not None else kernel.T
    return largest


def run_built(run: Built, observe=None, chunk: int = 0) -> Outcome:
    """Simulator.run of a built scene; with `observe`, its trajectory in chunks of `chunk`
    steps, the first with the row at t = 0, under [its index] (NaN rows after a step that
    raised: the sample's fault)."""
    sim = run.sim
    if observe is None:
        try:
            run.largest = sim.run(run.steps * sim.step_size)
        except Exception as raised:     # noqa: BLE001 (a sample's fault is its outcome)
            run.error = raised
        return run.outcome()
    start, done = np.array(run.start)[None], 0
    for part in parts(run.steps, chunk):
        rows = np.zeros((part, ROW))
        if run.error is None:
            try:
                run.largest = taken(sim, part, run.largest, rows)
            except Exception as raised:     # noqa: BLE001 (a sample's fault is its outcome)
                run.error = raised
        if run.error is not None:
            rows[max(0, sim.steps - done):] = np.nan
        done += part
        hand_out(observe, [run.index], done, sim.step_size,
                 (rows if start is None else np.concatenate([start, rows]))[None])
        start = None
    return run.outcome()


def taken(sim, part: int, largest: float, rows) -> float:
    """`part` steps of Simulator.run, each step's row into `rows`: compiled runs, or Python's
    steps (each row seen by the run's callback)."""
    if sim.kernel is not None:
        return advance(sim, part, largest, rows)
    seen = []
    try:
        return max(largest, sim.run(part * sim.step_size, lambda s: seen.append(row(s))))
    finally:
        rows[:len(seen)] = seen


def parts(steps: int, chunk: int) -> list[int]:
    """`steps` in chunks of `chunk` (at least one part: a run of 0 steps still has its t = 0)."""
    return [min(chunk, steps - done) for done in range(0, steps, chunk)] or [0]


def hand_out(observe, indices, steps: int, step_size: float, rows) -> None:
    """observe(indices, t, q, qd, tau) for rows (n, K, 6) whose last is at step `steps` (a
    first chunk has one row more: t = 0)."""
    count = rows.shape[1]
    t = np.arange(steps - count + 1, steps + 1) * step_size
    observe(indices, t, rows[:, :, 0:2], rows[:, :, 2:4], rows[:, :, 4:6])
