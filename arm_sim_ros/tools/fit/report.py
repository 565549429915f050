"""The report of `arm-sim fit`, read in a glance: measured against fitted per joint (each
segment simulated from its fitted start state, the held-out validation shaded), the
residuals in units of the noise, the parameter table with ± and units, and the cost over
the iterations of every start. As a PNG (matplotlib) or a Rerun recording (.rrd) with the
recordings' colours (recording/rrd/fit_report.py). The first recording is drawn.
"""
from __future__ import annotations

import numpy as np

from ...recording.rrd.fit_report import CHANNELS


def write_report(path, problem, outcome, names) -> None:
    series = traces(problem, outcome)
    if str(path).lower().endswith(".rrd"):
        from ...recording.rrd.fit_report import write_rrd
        write_rrd(path, series, outcome["cost_history"], table_rows(outcome), footnote(outcome),
                  names)
    else:
        write_png(path, series, outcome, names)


def traces(problem, outcome) -> dict:
    """Time, measured and fitted (NaN between segments) of the first recording."""
    rec = problem.recordings[0]
    measured = np.hstack([rec.q, rec.qd])
    fitted = np.full_like(measured, np.nan)
    validation = outcome["validation"]
    pairs = list(zip(problem.training, outcome["runs"]))
    if validation is not None:
        pairs += list(zip(problem.validation, validation["runs"]))
    for segment, run in pairs:
        if segment.recording == 0:
            fitted[segment.start:segment.stop] = run
    held = [g for g in problem.validation if g.recording == 0]
    return {"t": rec.t, "measured": measured, "fitted": fitted, "sigma": problem.sigma[0],
            "held_from": rec.t[held[0].start] if held else None, "source": rec.source,
            "segments": [
                rec.t[g.start] for g in problem.training if g.recording == 0]}


def table_rows(outcome) -> list[list[str]]:
    return [[p["key"], f"{p['value']:.6g}",
             f"± {p['se']:.2g}" if p["se"] == p["se"] else "not identified", p["unit"],
             f"{p['start']:.4g}"]
            for p in outcome["parameters"]]


def write_png(path, s, outcome, names) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(14, 11), layout="constrained")
    grid = fig.add_gridspec(4, 2, height_ratios=[3, 3, 2, 2.4])
    t = s["t"]
    for k, (short, title, unit) in enumerate(CHANNELS):
        joint = k % 2
        ax = fig.add_subplot(grid[k // 2, joint])
        ax.plot(t, s["measured"][:, k], ".", ms=1.5, color="0.55", label="measured")
        ax.plot(t, s["fitted"][:, k], lw=1.2, color=("tab:blue", "tab:orange")[joint],
                label="fitted (simulated)")
        _decorate(ax, s, f"{names[joint]}: {title} ({unit})")
        if k == 0:
            ax.legend(loc="upper right", fontsize=8)
    for joint in (0, 1):
        ax = fig.add_subplot(grid[2, joint])
        for k in (joint, 2 + joint):
            residual = (s["fitted"][:, k] - s["measured"][:, k]) / s["sigma"][k]
            ax.plot(t, residual, lw=0.5, alpha=0.8,
                    label=f"{CHANNELS[k][0]} / σ = {s['sigma'][k]:.2g} {CHANNELS[k][2]}")
        _decorate(ax, s, f"{names[joint]}: residual, fitted − measured (units of the noise σ)")
        ax.legend(loc="upper right", fontsize=8, ncol=2)
    ax = fig.add_subplot(grid[3, 0])
    history = np.asarray(outcome["cost_history"])
    ax.semilogy(np.arange(len(history)), history, "o-", ms=3, color="tab:green")
    ax.set_title(f"cost over iterations (best of {outcome['start_count']} starts; "
                 f"χ² per residual at the end {outcome['training']['chi2_per_residual']:.3f})",
                 fontsize=10)
    ax.set_xlabel("iteration")
    ax.set_ylabel("½ Σ r²")
    ax.grid(alpha=0.3)
    ax = fig.add_subplot(grid[3, 1])
    ax.axis("off")
    table = ax.table(cellText=table_rows(outcome), colLabels=["key", "value", "± 1 s.e.", "unit",
                                                              "start"], loc="upper center",
                     colWidths=[0.3, 0.18, 0.2, 0.17, 0.12])
    table.auto_set_font_size(False)
    table.set_fontsize(9)
    table.scale(1, 1.3)
    ax.text(0.0, 0.02, footnote(outcome), transform=ax.transAxes, fontsize=8, va="bottom",
            wrap=True)
    fig.suptitle(f"arm-sim fit: {s['source']}", fontsize=12)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def footnote(outcome) -> str:
    v = outcome["validation"]
    lines = []
    if v is not None:
        lines.append(f"validation, last {v['seconds']:.3g} s held out: RMS = "
                     + ", ".join(f"{m:.2f}" for m in v["noise_multiple"])
                     + " x the noise (q1, q2, qd1, qd2)")
    lines += [f"warning: {w}" for w in outcome["warnings"]]
    return "\n".join(line if len(line) < 110 else line[:107] + "..." for line in lines)


def _decorate(ax, s, title) -> None:
    ax.set_title(title, fontsize=10)
    if s["held_from"] is not None:
        ax.axvspan(s["held_from"], s["t"][-1], color="0.9", zorder=0, label=None)
    for start in s["segments"][1:]:
        ax.axvline(start, color="0.8", lw=0.5, zorder=0)
    ax.set_xlabel("t (s)")
    ax.grid(alpha=0.3)
