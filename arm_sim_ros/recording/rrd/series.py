"""Plain series on simulated time into a Rerun recording of their own: what a failing
controller test leaves (arm_sim_ros/testing/evidence.py), `rerun FILE.rrd` to look."""
from __future__ import annotations

import numpy as np
import rerun as rr


def write_series(path, times, series: dict, application_id: str = "arm_sim_test") -> None:
    """{entity path: values (N,) or (N, k)} at `times` (N,) s on the sim_time timeline."""
    stream = rr.RecordingStream(application_id)
    stream.save(str(path))
    index = rr.TimeColumn("sim_time", duration=np.asarray(times, dtype=float))
    for entity, values in series.items():
        stream.send_columns(entity, indexes=[index],
                            columns=rr.Scalars.columns(scalars=np.asarray(values, dtype=float)))
    stream.flush()
    stream.disconnect()
