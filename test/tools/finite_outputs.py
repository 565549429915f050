"""Where an output file holds a number that is not finite: `arm-sim run`'s CSV, its --json,
its Rerun recording and its bag (issue 47: no output file holds one). Each returns the
places found, empty when there are none."""
from __future__ import annotations

import csv
import math
from numbers import Number


def _numbers(value):
    """Every number in a nested value (lists, dicts, Arrow's lists of lists)."""
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return
    if isinstance(value, Number):
        yield float(value)
    elif isinstance(value, dict):
        for item in value.values():
            yield from _numbers(item)
    elif hasattr(value, "__iter__"):
        for item in value:
            yield from _numbers(item)


def csv_places(path) -> set:
    """The columns of a CSV with a cell that reads as a number that is not finite."""
    places = set()
    with open(path, newline="") as file:
        reader = csv.reader(file)
        header = next(reader)
        for row in reader:
            for name, cell in zip(header, row):
                try:
                    number = float(cell)
                except ValueError:
                    continue               # text, or empty: no number
                if not math.isfinite(number):
                    places.add(name)
    return places


# --json keys that are null by meaning, not for a number lost (a fault, an interrupted run,
# no error estimate: the steps not estimated)
ABSENT_BY_MEANING = ("fault", "interrupted_at", "error_estimate", "accumulated_error")


def json_places(result: dict) -> set:
    """The keys of a --json result whose number became null (strict JSON: not finite)."""
    def nulls(value, key):
        if value is None:
            yield key
        elif isinstance(value, dict):
            for k, v in value.items():
                yield from nulls(v, f"{key}.{k}" if key else k)
        elif isinstance(value, list):
            for v in value:
                yield from nulls(v, key)
    return {key for key in nulls(result, "") if key not in ABSENT_BY_MEANING}


def rrd_places(path) -> set:
    """The entities of a Rerun recording with a value that is not finite, in its rows or
    logged static (the 3D arm, styles, properties)."""
    from arm_sim_ros.recording.rrd import readback
    from recording.test_telemetry import read_back
    _, statics, _ = readback.read(path)
    return {f"{entity}:{name}" for table in (read_back(path), statics)
            for entity, columns in table.items() for name, values in columns.items()
            if not all(math.isfinite(v) for v in _numbers(values))}


def bag_places(path) -> set:
    """The topics and fields of a bag's messages with a number that is not finite (the
    diagnostics' values are text)."""
    from recording.test_bag import read_bag
    messages, _ = read_bag(path)
    places = set()
    for topic, entries in messages.items():
        for _, message, _ in entries:
            for field in ("position", "velocity", "effort", "data"):
                if not all(math.isfinite(v) for v in _numbers(getattr(message, field, ()))):
                    places.add(f"{topic}.{field}")
    return places
