"""One scene through Simulator.run: the reference every batched rollout equals, and the way
a scene that cannot batch runs."""
from __future__ import annotations

import numpy as np

from ..simulator import Simulator
from .outcomes import OBSERVE_STEPS, FirstFault, Outcome, one_line, outcome_of, refused

BUILD_ERRORS = (ValueError, ArithmeticError)   # a scene or value refused: its one line


def simulator_for(scene, duration: float):
    """(the scene's Simulator, the steps `duration` takes, its fault listener), or the
    refused Outcome."""
    try:
        sim = Simulator(scene)
        steps = scene.steps_for(duration, sim.step_size)
    except BUILD_ERRORS as error:
        return refused(one_line(error, named=False))
    first = FirstFault()
    sim.event_listeners.append(first)
    return sim, steps, first


def run_alone(scene, duration: float, index: int = 0, observe=None) -> Outcome:
    """Simulator.run of `scene` for `duration`; with `observe`, its trajectory in chunks of
    OBSERVE_STEPS steps (the first with the state at t = 0), under [index]."""
    built = simulator_for(scene, duration)
    if isinstance(built, Outcome):
        return built
    sim, steps, first = built
    recorder = None if observe is None else Recorder(sim, index, observe)
    largest, error, left = 0.0, None, steps
    try:
        while left:
            part = left if recorder is None else min(left, OBSERVE_STEPS)
            largest = max(largest, sim.run(part * sim.step_size,
                                           None if recorder is None else recorder.on_step))
            left -= part
            if recorder is not None:
                recorder.hand_out()
    except Exception as raised:     # noqa: BLE001 (a sample's fault is its row, never the sweep's)
        error = raised
    return outcome_of(sim, largest, first, error)


class Recorder:
    """The rows of a trajectory (t, q, qd, and the joint torque), handed to `observe` a chunk
    at a time; the first chunk begins with the state at t = 0."""

    def __init__(self, sim, index: int, observe):
        self.index, self.observe = [index], observe
        self.rows = []
        self.on_step(sim)

    def on_step(self, sim) -> None:
        self.rows.append((sim.time, *sim.state[0:4], *sim.joint_torque()))

    def hand_out(self) -> None:
        if not self.rows:
            return
        rows, self.rows = np.array(self.rows, dtype=float), []
        self.observe(self.index, rows[:, 0], rows[None, :, 1:3], rows[None, :, 3:5],
                     rows[None, :, 5:7])
