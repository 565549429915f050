"""The steps of an offline run as its recorders take them (tools/cli.run_recorded): each
step at once to a recorder with step(sim), a chunk's states together to one with
step_batch.

Every state the simulator keeps has passed the divergence check when it is made
(physics/trust/guard.py), so a step is handed over as it is taken: a diverged state never
reaches an output, and the step at which the check rolled back holds the last sound
state, as the node publishes it.
"""
from __future__ import annotations

from ...physics.simulator import recorded_row
from ...recording.readouts import error_books


class ChunkSteps:
    """The steps of one run_recorded chunk."""

    def __init__(self, each, batched: bool, every: int):
        """`each`: the step(sim) of the recorders without step_batch; `batched`: whether any
        has step_batch; `every`: the error books of every every-th step go with the states."""
        self.each, self.batched, self.every = each, batched, every
        self.states, self.books = [], []     # for recorders with step_batch: the chunk's

    def on_step(self, sim) -> None:
        if self.batched:
            self.states.append(recorded_row(sim))
            if self.every and sim.steps % self.every == 0:
                self.books.extend(error_books(sim))
        for step in self.each:
            step(sim)

    def hand_over(self, sim, batched) -> None:
        """At the chunk's end: its states to every recorder with step_batch."""
        if self.states:
            for recorder in batched:
                recorder.step_batch(sim, self.states, self.books)
        self.states, self.books = [], []
