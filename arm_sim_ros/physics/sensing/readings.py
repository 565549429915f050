"""The readings: the sensors' samples taken as the state reaches their times, and the one a
reading shows at each step (the latest taken `delay` or longer ago).

Sample 0 is taken at reset (t = 0), then one whenever `every` steps have passed since the
latest (sensors.rate; 1: every step). Before t = delay the reading is sample 0: the arm
stood in its initial state until t = 0. The sample index only counts up, across live
changes (a new noise, rate, delay or seed), so no change repeats or rewinds a stream; a
reset starts the run again at index 0, as a new run of the scene would. A delay that grows
live holds the reading until it is that old (a reading never goes back in time); one that
shrinks skips ahead.
"""
from __future__ import annotations

from collections import deque

from .sensors import SensorModel


class Readings:
    """Samples of one simulator's sensors, from its state; `current` is the reading now."""

    def __init__(self, model: SensorModel, carried: Readings | None = None):
        self.model = model
        if carried is not None:         # a live change: the samples and the index go on
            self.samples, self.index, self.last = carried.samples, carried.index, carried.last
            self.previous = carried.previous

    def reset(self, state) -> None:
        """Sample 0 of `state` at t = 0."""
        self.samples, self.index, self.previous, self.last = deque(), 0, None, 0
        self._take(0, state)

    def start(self, steps: int, state, index: int) -> None:
        """Sensors that begin to model something live, at step `steps`: sample `index` now."""
        self.samples, self.index, self.previous, self.last = deque(), index, None, steps
        self._take(steps, state)

    def catch_up(self, steps: int, state) -> None:
        """The state is `state` at step `steps`: its sample when one is due, and the reading
        `delay` steps back from there (called before the next step or a read: lazily)."""
        if steps - self.last >= self.model.every:
            self._take(steps, state)
        samples, due = self.samples, steps - self.model.delay
        while len(samples) > 1 and samples[1][0] <= due:
            samples.popleft()

    @property
    def current(self) -> tuple:
        """(q1, q2, q̇1, q̇2) as read now."""
        return self.samples[0][1]

    def _take(self, steps: int, state) -> None:
        model = self.model
        interval = (model.period if steps - self.last == model.every   # a live rate change:
                    else (steps - self.last) * model.step_size)        # the time since
        positions = model.positions(state, self.index)
        velocities = model.velocities(state[2:4], self.index, positions, self.previous,
                                      interval)
        self.samples.append((steps, (*positions, *velocities)))
        self.previous, self.last = positions, steps
        self.index += 1
