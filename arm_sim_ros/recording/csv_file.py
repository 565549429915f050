"""`--csv PATH`: one row per step of an offline run, every value as Python's repr (exact).

Columns: t, the state (q1, q2, qd1, qd2 and any extra state such as the winding currents
i1, i2), the joint torque, the energies, work and dissipated energy (0 where absent), every
other channel of the scene by name, and the balance residual.
"""
from __future__ import annotations

import csv

from ..usage import UsageError

CSV_COLUMNS = ("t", "q1", "q2", "qd1", "qd2", "tau1", "tau2", "kinetic", "potential", "total",
               "work", "dissipated", "residual")
BOOKS = ("work", "dissipated")


def csv_columns(sim) -> tuple[str, ...]:
    """The scene's columns: CSV_COLUMNS with its extra states and other channels added."""
    others = tuple(c for c in sim.channels if c not in BOOKS)
    return (CSV_COLUMNS[:5] + tuple(sim.extra) + CSV_COLUMNS[5:12] + others
            + CSV_COLUMNS[12:])


class CsvRecorder:
    """One row per step plus the initial row."""

    def __init__(self, path: str):
        self.path = path

    def start(self, sim) -> None:
        try:
            self._file = open(self.path, "w", newline="")
        except OSError as error:
            raise UsageError(f"cannot write --csv {self.path}: {error.strerror}") from None
        self._writer = csv.writer(self._file)
        self._others = [c for c in sim.channels if c not in BOOKS]
        self._writer.writerow(csv_columns(sim))
        self.step(sim)

    def step(self, sim) -> None:
        s = sim.sample()
        row = (s.t, *s.q, *s.qd, *s.extra.values(), *s.tau, s.kinetic, s.potential, s.total,
               s.work, s.dissipated, *(s.channels[c] for c in self._others), s.residual)
        self._writer.writerow([repr(v) for v in row])

    def finish(self, sim) -> None:
        self._file.close()
