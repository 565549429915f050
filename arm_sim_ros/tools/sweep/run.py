"""A sweep from start to table: the blocks still to run (all, or those --resume finds
missing), run where asked (pool.py), every finished block's rows kept, and the table
written sorted by index: every CHECKPOINT_SECONDS while it runs, and at the end however it
ends (done, Ctrl-C, a failure), so nothing finished is lost.
"""
from __future__ import annotations

import csv
import io
import json
import os
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from ...physics.scene import Scene
from .plan import Plan
from .rows import OUTCOMES, Task, header
from . import pool, table

CHECKPOINT_SECONDS = 10.0     # wall seconds between rewrites of the table while it runs
#                               (the first finished block is written at once)
FORMAT = 1                    # the table's layout; a resume needs the same


@dataclass(frozen=True)
class Sweep:
    """What a sweep is: every row depends on these and on nothing else."""

    base: Scene
    plan: Plan
    duration: float
    metrics: tuple
    after: float = 0.0

    @property
    def columns(self) -> tuple:
        return header(self.plan, self.metrics)

    def definition(self) -> dict:
        """The sweep as its sidecar records it: --resume goes on only the same sweep."""
        return {"format": FORMAT, "scene": asdict(self.base),
                "vary": [v.text for v in self.plan.varies], "seed": self.plan.seed,
                "draws": self.plan.draws, "duration": self.duration,
                "metrics": list(self.metrics), "after": self.after}

    def tasks(self, done=()) -> list:
        return [Task(self.base, self.plan, self.duration, self.metrics, self.after, first, stop)
                for first, stop in self.plan.blocks()
                if any(i not in done for i in range(first, stop))]


@dataclass
class SweepResult:
    """A sweep's result: the table as text (the bytes of its file), its columns parsed
    (numbers as float arrays, NaN where empty; text as lists), and how it went."""

    text: str
    columns: dict
    complete: bool
    ran: int                  # samples run by this call (not those resumed from the table)
    seconds: float            # wall seconds of this call's work
    compiling: float          # of the workers' seconds, those spent compiling kernels
    workers: str
    runs: list = field(default_factory=list)
    lost: str = ""            # why the work ended early other than by a stop, if it did

    @property
    def counts(self) -> dict:
        statuses = self.columns.get("status", [])
        return {s: sum(1 for x in statuses if x == s) for s in OUTCOMES}


def execute(sweep: Sweep, out=None, resume: bool = False, workers: int | None = 1, client=None,
            stop=None, progress=None) -> SweepResult:
    """Run the sweep; `out` (a path, or None: nothing written) gets the table (as soon as
    a block is done, then every CHECKPOINT_SECONDS and at the end) and its sidecar.
    `client`: a Dask cluster's (pool.connect) to run on, else local `workers` (None:
    every core, where the work is worth starting processes: pool.local).
    `stop.requested` (signals.StopOnSignals) ends it early."""
    stop = stop if stop is not None else _NeverStop()
    columns = sweep.columns
    lines, runs = {}, []
    if out is not None and resume and os.path.exists(out) and os.path.getsize(out):
        table.check_sidecar(out, sweep.definition())   # (an empty table: claimed, no rows)
        lines = table.read_done(out, columns)
        runs = _previous_runs(out)
    tasks = sweep.tasks(lines)
    if progress is not None:                   # what this call runs: a resume, the rest
        progress.total = sum(task.stop - task.first for task in tasks)
    used = {"processes": 1}                # where the blocks run: pool.local says
    if client is not None:
        used["address"] = client.scheduler.address
        used["processes"] = max(1, sum(w.get("nthreads", 1) for w in
                                       client.scheduler_info().get("workers", {}).values()))
        blocks = pool.cluster(tasks, client, stop)
    else:
        blocks = pool.local(tasks, workers, stop, used)
    started, last = time.perf_counter(), float("-inf")
    ran, compiling, working, failed, lost = 0, 0.0, 0.0, True, ""
    try:
        for done in blocks:
            if done is None:                   # none finished yet
                if progress is not None:
                    progress.update(ran)
                continue
            for row in done.rows:
                lines.setdefault(row[0], table.line(row))
            ran += done.stop - done.first
            compiling += done.compiling
            working += done.seconds - done.compiling
            if progress is not None:         # paced by the blocks' work, compiles left out
                progress.measured(working / used["processes"])
                progress.update(ran)
            if out is not None and time.perf_counter() - last > CHECKPOINT_SECONDS:
                _save(out, sweep, lines, runs, False, ran, time.perf_counter() - started,
                      compiling, _where(client, used))
                last = time.perf_counter()
        failed = False
    except pool.WorkersLost as error:     # the blocks done are kept; a resume runs the rest
        lost = str(error)
    finally:
        seconds = time.perf_counter() - started
        complete = not failed and len(lines) == sweep.plan.count
        if out is not None:
            runs = _save(out, sweep, lines, runs, complete, ran, seconds, compiling,
                         _where(client, used))
    text = table.text(columns, lines)
    return SweepResult(text, parse(text), complete, ran, seconds, compiling,
                       _where(client, used), runs, lost)


def _where(client, used: dict) -> str:
    if client is not None:
        return f"the Dask cluster at {used['address']} ({used['processes']} threads)"
    return f"{used['processes']} local processes" if used["processes"] > 1 else "this process"


def _save(out, sweep: Sweep, lines: dict, runs: list, complete: bool, ran: int,
          seconds: float, compiling: float, where: str) -> list:
    """The table as it stands and the sidecar: this run's timing after the earlier runs'."""
    this = {"samples_run": ran, "wall_seconds": round(seconds, 3),
            "compiling_seconds": round(compiling, 3), "where": where,
            "samples_per_second": round(ran / seconds, 3) if seconds > 0 else None}
    table.write(out, sweep.columns, lines)
    table.write_sidecar(out, sweep.definition(), {"complete": complete, "rows": len(lines),
                                                  "samples": sweep.plan.count,
                                                  "runs": runs + [this]})
    return runs + [this]


def _previous_runs(out) -> list:
    try:
        return list(json.loads(table.beside(out, table.SIDECAR).read_text())["runs"])
    except (OSError, ValueError, KeyError, TypeError):
        return []


TEXT_COLUMNS = ("status", "reason")


def parse(text: str) -> dict:
    """{column: values} of a table's text: a column of numbers (empty: NaN) as a float
    array, any other (status, reason, a varied name) as a list of text."""
    reader = csv.reader(io.StringIO(text))
    names = next(reader, [])
    cells = list(zip(*reader)) or [()] * len(names)
    found = {}
    for name, values in zip(names, cells):
        try:
            if name in TEXT_COLUMNS:
                raise ValueError(name)
            found[name] = np.array([float(v) if v else np.nan for v in values], dtype=float)
        except ValueError:
            found[name] = list(values)
    return found


class _NeverStop:
    requested = None
    within_step = False
