"""`--csv PATH`: one row per step of an offline run, every value as Python's repr (exact).

Columns: t, the state (q1, q2, qd1, qd2: the truth, and any extra state such as the winding
currents i1, i2), with sensors the readings (q1_measured, q2_measured, qd1_measured,
qd2_measured: physics/sensing/), the joint torque, the energies, work and dissipated energy (0 where absent), every
other channel of the scene by name, the balance residual, and the simulator's error books
after the step: error_estimate (the step's local error estimate) and accumulated_error
(their sum since reset), both max over q, qd (rad, rad/s); empty where the simulator does
not estimate the steps (estimate off, a refused step): no cell holds a number that is not
finite.

Rows are written in blocks of about BLOCK_BYTES. A write the disk refuses (a full disk,
a file-size limit) ends the run with one line: the file is cut back to the last whole row
that fit, and closed.
"""
from __future__ import annotations

import csv
import errno
import io
import os
import signal
import threading
from contextlib import suppress

from ..usage import UsageError

# A row, in CsvRecorder.step's order: the state (then any extra states), the torque and the
# energies (then the scene's other channels), the residual and the error books.
STATE_COLUMNS = ("t", "q1", "q2", "qd1", "qd2")
MEASURED_COLUMNS = ("q1_measured", "q2_measured", "qd1_measured", "qd2_measured")   # sensors
ENERGY_COLUMNS = ("tau1", "tau2", "kinetic", "potential", "total", "work", "dissipated")
CLOSING_COLUMNS = ("residual", "error_estimate", "accumulated_error")
CSV_COLUMNS = STATE_COLUMNS + ENERGY_COLUMNS + CLOSING_COLUMNS   # the bare arm's
BOOKS = ("work", "dissipated")
BLOCK_BYTES = 1 << 16


def let_writes_fail_on_file_size_limit() -> None:
    """Past a file-size limit (`ulimit -f`) the kernel sends SIGXFSZ, which kills the
    process mid-write; ignored, the write fails with EFBIG instead and the output can be
    closed whole and reported. (Only the main thread may set a signal's handler.)"""
    if hasattr(signal, "SIGXFSZ") and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)


def csv_columns(sim) -> tuple[str, ...]:
    """The scene's columns: CSV_COLUMNS with its extra states and other channels added."""
    others = tuple(c for c in sim.channels if c not in BOOKS)
    measured = MEASURED_COLUMNS if sim.scene.sensors is not None else ()
    return (STATE_COLUMNS + tuple(sim.extra) + measured + ENERGY_COLUMNS + others
            + CLOSING_COLUMNS)


class CsvRecorder:
    """One row per step plus the initial row."""

    def __init__(self, path: str):
        self.path = path
        self._file = None

    def start(self, sim) -> None:
        let_writes_fail_on_file_size_limit()
        try:
            self._file = open(self.path, "wb", buffering=0)
        except OSError as error:
            raise UsageError(f"cannot write --csv {self.path}: {error.strerror}") from None
        self._block = io.StringIO()
        self._writer = csv.writer(self._block)
        self._rows = 0             # whole rows in the file (the header one of them)
        self._last = b""          # the last block written
        self._others = [c for c in sim.channels if c not in BOOKS]
        self._writer.writerow(csv_columns(sim))
        self.step(sim)

    def step(self, sim) -> None:
        s = sim.sample()
        row = (s.t, *s.q, *s.qd, *s.extra.values(), *(s.measured or ()), *s.tau, s.kinetic,
               s.potential, s.total,
               s.work, s.dissipated, *(s.channels[c] for c in self._others), s.residual)
        books = (sim.error_estimate, sim.accumulated_error)     # NaN: not estimated, empty
        self._writer.writerow([repr(v) for v in row] + ["" if v != v else repr(v) for v in books])
        if self._block.tell() >= BLOCK_BYTES:
            self._flush()

    def finish(self, sim) -> None:
        if self._file is None or self._file.closed:   # never opened, or closed by a failure
            return
        try:
            self._flush()
        finally:
            self._file.close()

    def _flush(self) -> None:
        data = self._block.getvalue().encode()
        self._block.seek(0)
        self._block.truncate()
        done = 0
        try:
            while done < len(data):
                written = self._file.write(data[done:])
                if not written:
                    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
                done += written
        except BrokenPipeError:    # a reader that went away: the caller ends quietly
            raise
        except OSError as error:
            self._fail(error, data[:done])
        self._rows += data.count(b"\n")
        self._last = data or self._last

    def _fail(self, error: OSError, written: bytes):
        """Cut the file back to its last whole row, close it and say what it holds."""
        whole = written.rfind(b"\n") + 1
        rows = self._rows + written.count(b"\n", 0, whole)
        with suppress(OSError):    # (a pipe cannot be cut)
            self._file.truncate(self._file.tell() - len(written) + whole)
        self._file.close()
        last = (written[:whole] or self._last).splitlines()[-1:] if rows > 1 else []
        until = f" (up to t = {last[0].split(b',')[0].decode()} s)" if last else ""
        raise UsageError(f"cannot write --csv {self.path}: {error.strerror or error}; the file "
                         f"is closed and holds the {rows - 1 if rows else 0} rows that fit"
                         f"{until}") from None
