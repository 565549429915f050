"""`--csv PATH`: one row per step of an offline run, every value as Python's repr (exact)."""
from __future__ import annotations

import csv

from ..usage import UsageError

CSV_COLUMNS = ("t", "q1", "q2", "qd1", "qd2", "tau1", "tau2", "kinetic", "potential", "total",
               "work", "dissipated", "residual")


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
        self._writer.writerow(CSV_COLUMNS)
        self.step(sim)

    def step(self, sim) -> None:
        s = sim.sample()
        self._writer.writerow([repr(v) for v in (s.t, *s.q, *s.qd, *s.tau, s.kinetic, s.potential,
                                                 s.total, s.work, s.dissipated, s.residual)])

    def finish(self, sim) -> None:
        self._file.close()
