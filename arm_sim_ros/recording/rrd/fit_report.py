"""The Rerun recording of an `arm-sim fit` report (tools/fit/report.py draws the same as a
PNG): per joint the measured and fitted angle and velocity on the `sim_time` timeline, the
residuals in units of the noise, the cost over the iterations as bars (log10) and the parameter
table as a document; the joints' colours and the collapsed panels of the run recordings
(blueprint.py).
"""
from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from .blueprint import JOINT_COLORS, TIMELINE
from .columns import scalars

MEASURED = (150, 150, 150)
CHANNELS = (("q1", "shoulder angle", "rad"), ("q2", "elbow angle", "rad"),
            ("qd1", "shoulder velocity", "rad/s"), ("qd2", "elbow velocity", "rad/s"))


def write_rrd(path, s, history, rows, footnote: str, names) -> None:
    """`s`: t, measured and fitted (n, 4), sigma (4,), as fit_report.traces gives them;
    `history` the cost per iteration; `rows` the parameter table's rows."""
    stream = rr.RecordingStream("arm_sim_fit")
    index = [rr.TimeColumn(TIMELINE, duration=s["t"])]
    views = []
    for k, (short, title, unit) in enumerate(CHANNELS):
        joint = k % 2
        path_k = f"fit/{short}"
        stream.log(path_k, rr.SeriesLines(names=["measured", "fitted"], widths=[4.0, 1.5],
                                          colors=[MEASURED, JOINT_COLORS[joint]]), static=True)
        stream.send_columns(path_k, indexes=index, columns=scalars(
            np.column_stack([s["measured"][:, k], s["fitted"][:, k]])))
        views.append(rrb.TimeSeriesView(name=f"{names[joint]}: {title} ({unit})", origin=path_k))
    residual = (s["fitted"] - s["measured"]) / s["sigma"]
    stream.log("fit/residual", rr.SeriesLines(
        names=[f"{c[0]} / sigma" for c in CHANNELS], colors=[
            JOINT_COLORS[0], JOINT_COLORS[1], (40, 130, 255), (255, 110, 40)]), static=True)
    stream.send_columns("fit/residual", indexes=index, columns=scalars(residual))
    # The cost spans decades and has no place on sim_time: a bar per iteration, log10.
    stream.log("fit/cost", rr.BarChart(np.log10(np.maximum(history, 1e-300))), static=True)
    header = "| key | value | ± 1 s.e. | unit | start |\n|---|---|---|---|---|\n"
    text = header + "".join(f"| {' | '.join(row)} |\n" for row in rows)
    stream.log("fit/parameters", rr.TextDocument(text + "\n" + footnote.replace(
        "\n", "\n\n"), media_type=rr.MediaType.MARKDOWN), static=True)
    blueprint = rrb.Blueprint(
        rrb.Vertical(rrb.Grid(*views, grid_columns=2),
                     rrb.Horizontal(rrb.TimeSeriesView(name="Residual (units of the noise)",
                                                       origin="fit/residual"),
                                    rrb.BarChartView(name="log10 cost over iterations",
                                                     origin="fit/cost"),
                                    rrb.TextDocumentView(name="Parameters", origin="fit/parameters")),
                     row_shares=[3, 1]),
        rrb.TimePanel(timeline=TIMELINE, state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"))
    stream.save(str(path), default_blueprint=blueprint)
    stream.flush()
    stream.disconnect()
