"""The sweep's table: one CSV, a row per sample sorted by index, the same bytes however
and wherever it was computed; and its sidecar JSON, what the sweep was and how long it
took (wall time is not the samples': it stays out of the table).

CSV, not Parquet: it needs nothing installed to write or read (pandas, polars, numpy,
a spreadsheet), its bytes are ours alone (a Parquet writer stamps its own version and
layout into the file, so the bytes would follow the library, not the samples), and a
resumed sweep reads its rows back as text and writes them unchanged. Numbers are
written as Python's repr (the shortest text that reads back to the same double); NaN
is an empty cell (a figure with no reference, an estimate that is off), which pandas and
polars read as missing.
"""
from __future__ import annotations

import csv
import io
import json
from math import isnan
from pathlib import Path

from ...outputs import strict_json, write_text
from ...physics.scene import SceneError

SIDECAR = ".json"
PICTURE = ".png"


def cell(value) -> str:
    """A value as the table writes it: repr of a double (NaN: empty), whole numbers and
    text as they are."""
    if isinstance(value, float):          # numpy's doubles too: their repr names numpy
        return "" if isnan(value) else repr(float(value))
    return str(value)


def line(values) -> str:
    stream = io.StringIO()
    csv.writer(stream, lineterminator="\n").writerow(
        [v if isinstance(v, str) else cell(v) for v in values])
    return stream.getvalue()


def text(columns, lines: dict) -> str:
    """The whole table: the header, then every row's line in index order."""
    return line(columns) + "".join(lines[index] for index in sorted(lines))


def beside(path, suffix: str) -> Path:
    """The sidecar or the picture beside the table: runs/x.csv -> runs/x.json."""
    return Path(path).with_suffix(suffix)


def write(path, columns, lines: dict, option: str = "-o") -> None:
    write_text(path, text(columns, lines), option)


def read_done(path, columns) -> dict:
    """{index: the row's line as written} of a table a sweep wrote before, or SceneError
    when it is not that sweep's table (another header, a damaged row)."""
    try:
        content = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise SceneError(f"--resume: cannot read {path} ({error})") from None
    raw = content.splitlines(keepends=True)
    if not raw:
        return {}
    if raw[0] != line(columns):
        raise SceneError(f"--resume: {path} has other columns than this sweep's; resume a "
                         "sweep with the options that started it, or write a new -o")
    done = {}
    for number, (row, original) in enumerate(zip(csv.reader(io.StringIO("".join(raw[1:]))),
                                                 _records(raw[1:])), start=2):
        if len(row) != len(columns) or not row[0].isdigit() or not original.endswith("\n"):
            continue              # a line cut short when the run stopped: run it again
        done[int(row[0])] = original
    return done


def _records(lines: list):
    """The text of each CSV record (a quoted reason may hold a line break)."""
    record = ""
    for piece in lines:
        record += piece
        if record.count('"') % 2 == 0:
            yield record
            record = ""
    if record:
        yield record


def write_sidecar(path, definition: dict, progress: dict) -> None:
    write_text(beside(path, SIDECAR), strict_json({"sweep": definition, **progress}, indent=1)
               + "\n", "-o (its sidecar)")


def check_sidecar(path, definition: dict) -> None:
    """--resume only the sweep that wrote `path`: its sidecar names the same sweep."""
    sidecar = beside(path, SIDECAR)
    try:
        written = json.loads(sidecar.read_text(encoding="utf-8"))["sweep"]
    except (OSError, ValueError, KeyError, TypeError):
        raise SceneError(f"--resume: {sidecar} is missing or unreadable, so nothing says "
                         f"which sweep wrote {path}; write a new -o") from None
    wanted = json.loads(strict_json(definition))
    if written != wanted:
        differ = sorted(k for k in set(written) | set(wanted) if written.get(k) != wanted.get(k))
        raise SceneError(f"--resume: {path} was written by another sweep (its {', '.join(differ)}"
                         " differ); resume it with the options that started it, or write a "
                         "new -o")
