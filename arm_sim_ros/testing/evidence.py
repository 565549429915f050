"""What a failing controller test leaves behind, in pytest's tmp dir: its trace as CSV
(every value exact), a Rerun recording (`rerun FILE.rrd`) and a PNG of q, the reference and
the torques; the failure message names them."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .trace import COLUMNS, Trace


def write(trace: Trace, directory, stem: str) -> dict:
    """{"csv", "png", "rrd": path} written for `trace` (a recording it has already, the
    node's over the wire, is named, not written again)."""
    directory = Path(directory)
    paths = {"csv": directory / f"{stem}.csv", "png": directory / f"{stem}.png"}
    write_csv(trace, paths["csv"])
    write_png(trace, paths["png"])
    if "rrd" in trace.evidence:
        paths["rrd"] = Path(trace.evidence["rrd"])
    else:
        paths["rrd"] = directory / f"{stem}.rrd"
        write_rrd(trace, paths["rrd"])
    return {kind: str(path) for kind, path in paths.items()}


def write_csv(trace: Trace, path) -> None:
    np.savetxt(path, trace.rows(), fmt="%.17g", delimiter=",", header=",".join(COLUMNS),
               comments="")



def write_png(trace: Trace, path) -> None:
    import matplotlib
    matplotlib.use("Agg", force=False)
    from matplotlib import pyplot as plt

    figure, (angles, torques) = plt.subplots(2, 1, sharex=True, figsize=(9, 6))
    colours = ("tab:cyan", "tab:orange")
    for joint, colour in enumerate(colours):
        angles.plot(trace.t, trace.q[:, joint], color=colour, label=f"q{joint + 1}")
        if not np.array_equal(trace.measured_q[:, joint], trace.q[:, joint]):
            angles.plot(trace.t, trace.measured_q[:, joint], color=colour, alpha=0.5,
                        linewidth=0.8, label=f"q{joint + 1} read")
        if trace.reference is not None:
            angles.plot(trace.t, trace.reference[:, joint], color=colour, linestyle="--",
                        label=f"q{joint + 1} reference")
        torques.plot(trace.t, trace.tau[:, joint], color=colour, label=f"tau{joint + 1}")
    angles.set_ylabel("rad")
    torques.set_ylabel("N m")
    torques.set_xlabel("t [s]")
    angles.set_title(f"{trace.scene}: q, reference and the torque the joints received")
    for axes in (angles, torques):
        axes.grid(alpha=0.3)
        axes.legend(loc="best", fontsize="small")
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def write_rrd(trace: Trace, path) -> None:
    from ..recording.rrd.series import write_series
    series = {"joints/angle": trace.q, "joints/velocity": trace.qd,
              "joints/angle_read": trace.measured_q, "joints/command": trace.command,
              "joints/torque": trace.tau}
    if trace.reference is not None:
        series["joints/reference"] = trace.reference
    series |= {f"energy/{name}": values for name, values in trace.energy().items()}
    write_series(path, trace.t, series)
