"""A Rerun recording of this package read back (rr.chunk.RrdReader, 0.41): its properties
(properties.py wrote them) and its scalar series as one table on simulated time, for
`arm-sim inspect` and the tests.

table(read(path)) gives one row per simulated time at which any series has a value:
sim_time (s), ros_time and log_time (ns since the epoch; empty where a recording lacks
them), then every series' values, a column per component, headed `entity path:series
name [unit]` (the series names and units are the recording's own static SeriesLines names
and `unit` values).
"""
from __future__ import annotations

import warnings
from collections import defaultdict

import pyarrow as pa
import rerun as rr

from .blueprint import LOG_TIME, ROS_TIME, TIMELINE

PROPERTIES = "/__properties"
SCALARS = "Scalars:scalars"
TIMES = (TIMELINE, ROS_TIME, LOG_TIME)


class RecordingError(ValueError):
    """The file is not a Rerun recording this can read."""


def _reader(path):
    try:
        with warnings.catch_warnings():    # a node's file has no footer (sinks.py): streamed
            warnings.filterwarnings("ignore", "RRD file has no footer")
            reader = rr.chunk.RrdReader(str(path))
        recordings = reader.recordings()
    except Exception as error:  # rerun raises its own kinds for a missing or bad file
        raise RecordingError(f"{path}: not a readable Rerun recording ({error})") from None
    if not recordings:
        raise RecordingError(f"{path}: holds no recording")
    return reader, recordings[0]


def _plain(column):
    """A column's values as Python: durations and timestamps as integer ns."""
    if pa.types.is_duration(column.type) or pa.types.is_timestamp(column.type):
        column = column.cast(pa.int64())
    return column.to_pylist()


def _single(value):
    return value[0] if isinstance(value, list) and len(value) == 1 else value


def read(path):
    """(properties, statics, temporal): {property: {key: value}}, {entity: {column: value}}
    of the static rows, and {entity: [(column names, {column: values})]} of the rest."""
    reader, recording = _reader(path)
    props, statics, temporal = defaultdict(dict), defaultdict(dict), defaultdict(list)
    for chunk in reader.stream(store=recording):
        entity, batch = chunk.entity_path, chunk.to_record_batch()
        names = [n for n in batch.schema.names if n != "rerun.controls.RowId"]
        if chunk.is_static:
            target = (props[entity[len(PROPERTIES):].lstrip("/").replace("\\", "") or "recording"]
                      if entity.startswith(PROPERTIES) else statics[entity.lstrip("/")])
            for name in names:
                values = _plain(batch.column(name))
                if values:
                    target[name.removeprefix("RecordingInfo:")] = _single(values[-1])
        else:
            temporal[entity.lstrip("/")].append({n: _plain(batch.column(n)) for n in names})
    order = ["recording", "scene", "integrator", "effects"]
    rank = {name: (order.index(name) if name in order else len(order) + (name == "units"), name)
            for name in props}
    return {name: props[name] for name in sorted(props, key=rank.get)}, dict(statics), \
        dict(temporal)


def properties(path) -> dict:
    """{property: {key: value}} of the recording (its name and start time as `recording`),
    the scene, integrator and effects first."""
    return read(path)[0]


def headers(entity: str, static: dict, width: int) -> list[str]:
    names = static.get("SeriesLines:names") or []
    names = names if isinstance(names, list) else [names]
    unit = static.get("unit")
    suffix = f" [{unit}]" if unit else ""
    if width == 1:
        return [f"{entity}:{names[0]}{suffix}" if names else f"{entity}{suffix}"]
    return [f"{entity}:{names[i] if i < len(names) else i}{suffix}" for i in range(width)]


def table(recording):
    """(header, rows) of a recording's scalar series on simulated time (see the module's
    docstring), from what read() gave; rows in sim_time order, None where a series has no
    value at that time."""
    props, statics, temporal = recording
    listed = props.get("units", {}).get("path") or []
    listed = [listed] if isinstance(listed, str) else listed   # the units' order first
    times, values, columns = {}, defaultdict(dict), {}
    for entity in sorted(temporal, key=lambda e: (listed.index(e) if e in listed
                                                  else len(listed), e)):
        for part in temporal[entity]:
            if SCALARS not in part or TIMELINE not in part:
                continue
            for k, (t, row) in enumerate(zip(part[TIMELINE], part[SCALARS])):
                stamps = tuple(part[name][k] if name in part else None for name in TIMES[1:])
                old = times.get(t, (None, None))
                times[t] = tuple(a if a is not None else b for a, b in zip(stamps, old))
                values[t][entity] = row
                columns.setdefault(entity, len(row))
    header = ["sim_time [s]", "ros_time [ns]", "log_time [ns]"]
    for entity, width in columns.items():
        header += headers(entity, statics.get(entity, {}), width)
    rows = []
    for t in sorted(times):
        row = [t / 1e9, *times[t]]
        for entity, width in columns.items():
            got = values[t].get(entity)
            row += list(got) if got is not None else [None] * width
        rows.append(row)
    return header, rows
