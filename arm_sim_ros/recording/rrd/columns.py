"""Arrays as Rerun columns, built as Arrow directly: rerun's Archetype.columns() converts
through Python (strip by strip for line strips) and costs 3-10x as much; this runs in the
sender thread, where every microsecond holding the GIL is one the simulation waits for.
"""
from __future__ import annotations

import numpy as np
import pyarrow as pa
import rerun as rr

from .blueprint import LOG_TIME, ROS_TIME, TIMELINE


def nanoseconds(seconds):
    """Simulated seconds as the timeline's integer nanoseconds (exact for steps x h)."""
    return np.rint(seconds * 1e9).astype("timedelta64[ns]")


def time_columns(ns, wall_ns, stamp_origin_ns=None):
    """The rows' timelines: sim_time (`ns`, timedelta64), log_time (`wall_ns`, ns since the
    epoch) and, with a stamp origin, ros_time = stamp_origin_ns + sim_time."""
    columns = [rr.TimeColumn(TIMELINE, duration=ns),
               rr.TimeColumn(LOG_TIME, timestamp=wall_ns.astype("datetime64[ns]"))]
    if stamp_origin_ns is not None:
        stamps = ns.astype(np.int64) + np.int64(stamp_origin_ns)
        columns.append(rr.TimeColumn(ROS_TIME, timestamp=stamps.astype("datetime64[ns]")))
    return columns


def _column(descriptor, batch, items: int, per_row: int):
    """`items` components of `batch`, `per_row` of them in each row."""
    offsets = np.arange(0, items + 1, per_row, dtype=np.int32)
    return [rr.ComponentColumn(descriptor, batch, offsets=offsets)]


def scalars(values):
    """A Scalars column: one row per entry of (n,) values, or per row of (n, k)."""
    flat = np.ascontiguousarray(values, dtype=float).reshape(-1)
    return _column(rr.Scalars.descriptor_scalars(), rr.components.ScalarBatch(pa.array(flat)),
                   flat.size, flat.size // len(values))


def text_lines(lines):
    """[(text, level)] as a TextLog column set of one line per row."""
    return rr.TextLog.columns(text=[text for text, _ in lines], level=[level for _, level in lines])


def _vertices(points, kind):
    """(..., 2) points as Arrow float32 pairs of `kind`."""
    flat = pa.array(np.ascontiguousarray(points, dtype=np.float32).reshape(-1))
    return pa.FixedSizeListArray.from_arrays(flat, type=kind)


def points(positions):
    """(rows, k, 2) positions as a Points2D positions column of k points per row."""
    kind = rr.components.Position2DBatch._ARROW_DATATYPE
    rows, k = positions.shape[:2]
    return _column(rr.Points2D.descriptor_positions(),
                   rr.components.Position2DBatch(_vertices(positions, kind)), rows * k, k)


def strips(points, strips_per_row=1):
    """Two-point line strips, (rows, 2 x strips_per_row, 2) points, as one LineStrips2D
    column."""
    kind = rr.components.LineStrip2DBatch._ARROW_DATATYPE
    count = points.shape[0] * strips_per_row
    batch = pa.ListArray.from_arrays(pa.array(np.arange(0, 2 * count + 1, 2, dtype=np.int32)),
                                     _vertices(points, kind.value_type), type=kind)
    return _column(rr.LineStrips2D.descriptor_strips(), rr.components.LineStrip2DBatch(batch),
                   count, strips_per_row)


def vectors3d(vectors):
    """(rows, 3) vectors as an Arrows3D vectors column of one arrow per row."""
    kind = rr.components.Vector3DBatch._ARROW_DATATYPE
    return _column(rr.Arrows3D.descriptor_vectors(),
                   rr.components.Vector3DBatch(_vertices(vectors, kind)), len(vectors), 1)


def joint_transforms(xyzw, translation, parent: str, child: str):
    """A Transform3D column set of one transform per row: (rows, 4) rotations, a fixed
    translation and the frames it joins (the viewer needs those in each row)."""
    rows = len(xyzw)
    rotation = rr.components.RotationQuatBatch(
        _vertices(xyzw, rr.components.RotationQuatBatch._ARROW_DATATYPE))
    shift = rr.components.Translation3DBatch(_vertices(
        np.broadcast_to(np.asarray(translation, np.float32), (rows, 3)),
        rr.components.Translation3DBatch._ARROW_DATATYPE))
    frames = [rr.components.TransformFrameIdBatch(
        pa.DictionaryArray.from_arrays(np.zeros(rows, np.int32), pa.array([name])).cast(pa.utf8()))
        for name in (parent, child)]
    return (_column(rr.Transform3D.descriptor_quaternion(), rotation, rows, 1)
            + _column(rr.Transform3D.descriptor_translation(), shift, rows, 1)
            + _column(rr.Transform3D.descriptor_parent_frame(), frames[0], rows, 1)
            + _column(rr.Transform3D.descriptor_child_frame(), frames[1], rows, 1))
