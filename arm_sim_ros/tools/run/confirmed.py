"""Rows of an offline run held until the divergence check confirms them.

The simulator checks for divergence every guard.CHECK_EVERY steps (and at the end of each
run() call); a diverged check rolls the state back to the last sound one. The steps taken
since that sound state are then retracted: they must never reach a CSV, a bag or a
recording. So run_recorded hands a recorder a step only once the state is confirmed
(Simulator.confirmed), and drops the retracted ones; the step the check rolled back at (the
sound state, held from then on) is kept, as the node publishes it.
"""
from __future__ import annotations

from ...physics.simulator import recorded_row, sample
from ...recording.readouts import error_books


class StepView:
    """One step of `sim` as a recorder reads it, frozen when it was taken: state, time,
    refusals and error books; what does not change from step to step is read from `sim`."""

    def __init__(self, sim):
        self._sim = sim
        self.state, self.steps, self.holding = sim.state, sim.steps, sim.holding
        self.readings = sim.readings      # with sensors: as read after the step
        self._torque = sim.joint_torque()  # under a control loop it changes every step
        self.fault, self.refused_steps = sim.fault, sim.refused_steps
        _, self.error_estimate, self.accumulated_error, self.substeps_taken = error_books(sim)

    def __getattr__(self, name):
        return getattr(self._sim, name)

    @property
    def time(self) -> float:
        return self.steps * self._sim.step_size

    def sample(self):
        return sample(self)

    def joint_torque(self, state=None):
        return self._torque if state is None or state is self.state else \
            self._sim.joint_torque(state)

    def residual(self, state=None) -> float:
        return self._sim.residual(self.state if state is None else state)


class ConfirmedSteps:
    """The steps of one run_recorded chunk, released to the recorders as they are confirmed."""

    def __init__(self, sim, each, batched: bool, every: int):
        """`each`: the step(sim) of the recorders without step_batch; `batched`: whether any
        has step_batch; `every`: the error books of every every-th step go with the states."""
        self.sim, self.each, self.batched, self.every = sim, each, batched, every
        self.states, self.books = [], []     # for recorders with step_batch: the chunk's
        self.steps = []                      # ...and their step numbers
        self.waiting = []                    # StepViews not yet confirmed (recorders with step)
        self.diverged = sim.diverged
        self.sound = sim.steps               # the latest step the check confirmed

    def on_step(self, sim) -> None:
        if self.batched:                     # a recorder with step_batch takes them
            self.states.append(recorded_row(sim))
            self.steps.append(sim.steps)
            if self.every and sim.steps % self.every == 0:
                self.books.extend(error_books(sim))
        if self.each:
            self.waiting.append(StepView(sim))
        if sim.diverged is not self.diverged:    # rolled back: what followed the sound state
            self.diverged = sim.diverged
            self._retract(sim)
        if sim.confirmed:
            self.sound = sim.steps
            self.release()

    def _retract(self, sim) -> None:
        """Drop the steps after the last confirmed one, but the one now (the sound state)."""
        def kept(step):
            return step <= self.sound or step == sim.steps

        self.waiting = [view for view in self.waiting if kept(view.steps)]
        keep = [i for i, step in enumerate(self.steps) if kept(step)]
        self.states = [self.states[i] for i in keep]
        self.steps = [self.steps[i] for i in keep]
        self.books = [value for k in range(0, len(self.books), 4) if kept(self.books[k])
                      for value in self.books[k:k + 4]]

    def release(self) -> None:
        """The confirmed steps to the recorders with step(sim)."""
        for view in self.waiting:
            for step in self.each:
                step(view)
        self.waiting = []

    def hand_over(self, batched) -> None:
        """At the chunk's end (run() checks before it returns): everything to every
        recorder; step_batch once per run of consecutive steps."""
        sim = self.sim
        if sim.diverged is not self.diverged:    # run()'s own last check rolled back: the
            self.diverged = sim.diverged         # last step taken is now the sound state
            self._retract(sim)
            if self.waiting and self.waiting[-1].steps == sim.steps:
                self.waiting[-1] = StepView(sim)
            if self.steps and self.steps[-1] == sim.steps:
                self.states[-1] = recorded_row(sim)
        self.release()
        runs, start = [], 0
        for i in range(1, len(self.steps) + 1):
            if i == len(self.steps) or self.steps[i] != self.steps[i - 1] + 1:
                runs.append((start, i))
                start = i
        for first, end in runs:
            last = self.steps[end - 1]
            books = [value for k in range(0, len(self.books), 4)
                     for value in self.books[k:k + 4]
                     if self.steps[first] <= self.books[k] <= last]
            for recorder in batched:
                if last == self.sim.steps:
                    recorder.step_batch(self.sim, self.states[first:end], books)
                else:                        # rows before a retracted stretch
                    recorder.step_batch(self.sim, self.states[first:end], books, last=last)
        self.states, self.books, self.steps = [], [], []
