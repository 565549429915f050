"""What the accuracy study (accuracy.py) shows: its table per scene, the price list across
scenes, and the work-precision diagram, one panel per scene."""
from __future__ import annotations

import textwrap
import zlib
from math import ceil, isfinite, log10
from pathlib import Path

from ...usage import UsageError

PANEL_SIZE = (6.4, 4.6)          # inches per panel
MAX_COLUMNS = 2
TARGET = 1e-6                   # the price list: the cheapest run at least this accurate


def _number(value, spec: str, width: int) -> str:
    return f"{'—':>{width}}" if value is None else f"{value:>{width}{spec}}"


def format_table(result: dict) -> str:
    header = (f"{'method':<28} {'h (s)':>9} {'tol':>7} {'max |state err|':>15} "
              f"{'energy drift J':>14} {'residual J':>10} {'rhs evals':>9} {'sub-steps':>9} "
              f"{'CPU s/sim s':>11}")
    lines = [f"scene {result['scene']}, {result['duration']:g} s, compared every "
             f"{result['sample_interval']:g} s with {result['reference']}", header,
             "-" * len(header)]
    for r in result["runs"]:
        tol = "" if r["tolerance"] is None else f"{r['tolerance']:.0e}"
        lines.append(f"{r['series']:<28} {r['step_size']:>9g} {tol:>7} "
                     f"{r['max_state_error']:>15.3e} {_number(r['energy_drift'], '.3e', 14)} "
                     f"{_number(r['balance_residual'], '.2e', 10)} "
                     f"{_number(r['rhs_evaluations'], 'd', 9)} {_number(r['substeps'], 'd', 9)} "
                     f"{r['cpu_s_per_sim_s']:>11.2e}")
    lines.append("")
    for name, o in result["orders"].items():
        fitted = "n/a (too few points in range)" if o["fitted"] is None else f"{o['fitted']:.2f}"
        lines.append(f"fitted order {name:<20} {fitted}  (theory {o['theory']})")
    mujoco = result["peers"].get("mujoco", {})
    if "version" in mujoco:
        lines.append(f"MuJoCo {mujoco['version']}: mj_step, one Python call per step"
                     + "".join(f"; {note}" for note in mujoco["notes"]))
    if "floor" in mujoco:
        lines.append(f"MuJoCo's error floor here: {mujoco['floor']:.2e} (its soft constraints "
                     "follow their own law: the error stops falling with h)")
    lines += result["notes"]
    best = cheapest(result, TARGET)
    if best:
        lines.append(f"cheapest run with max state error <= {TARGET:g}: {best['series']} "
                     f"h={best['step_size']:g}"
                     + (f" tol={best['tolerance']:g}" if best["tolerance"] else "")
                     + f" ({best['cpu_s_per_sim_s']:.2e} CPU s per simulated s)")
    return "\n".join(lines)


def cheapest(result: dict, target: float, runs=None):
    """The run reaching max state error <= target at the least CPU time, or None."""
    good = [r for r in (result["runs"] if runs is None else runs)
            if r["max_state_error"] <= target]
    return min(good, key=lambda r: r["cpu_s_per_sim_s"], default=None)


def pick(result: dict, target: float, kind: str, integrator: str | None = None) -> dict | None:
    """Of the runs of `kind` (of `integrator`, if given): the cheapest at least `target`
    accurate, else the most accurate one (None if none ran)."""
    runs = [r for r in result["runs"] if r["kind"] == kind
            and integrator in (None, r["integrator"])]
    return cheapest(result, target, runs) or min(runs, key=lambda r: r["max_state_error"],
                                                 default=None)


def price_columns(result: dict, target: float) -> list:
    """(label, run) per column of the price list for one scene."""
    as_set = next((r for r in result["runs"] if r["kind"] == "as set"), None)
    at_h = as_set["step_size"] if as_set else None
    mujoco_at_h = [r for r in result["runs"] if r["kind"] == "mujoco" and r["step_size"] == at_h]
    return [("ours as set", as_set),
            ("ours rk4 + tolerance", pick(result, target, "tolerance", "rk4")),
            ("ours dopri5", pick(result, target, "method", "dopri5")),
            ("MuJoCo best at the scene's h", min(mujoco_at_h, default=None,
                                                key=lambda r: r["max_state_error"])),
            ("MuJoCo cheapest", pick(result, target, "mujoco"))]


def price_list(results: list, target: float) -> str:
    """Per scene and column: error, µs per simulated second and which run it is."""
    lines = [f"price list: max |state error| and CPU µs per simulated second; per column the "
             f"cheapest run reaching {target:g}, else its most accurate", ""]
    for result in results:
        lines.append(f"{result['scene']}:")
        for label, run in price_columns(result, target):
            if run is None:
                lines.append(f"  {label:<30} —")
                continue
            what = f"h={run['step_size']:g}" + (f" tol={run['tolerance']:g}"
                                                if run["tolerance"] else "")
            lines.append(f"  {label:<30} {run['max_state_error']:>9.1e} "
                         f"{run['cpu_s_per_sim_s'] * 1e6:>10.0f} µs/s  {run['series']} {what}")
    return "\n".join(lines)


def check_plotting() -> None:
    """Refuse --plot in one line, before any work, when matplotlib cannot be imported."""
    try:
        import matplotlib  # noqa: F401
    except ImportError as error:
        raise UsageError(f"--plot needs matplotlib ({error.msg}): pip install "
                         "matplotlib==3.11.2, or reinstall arm_sim_ros") from None


def write_plot(results: list, path) -> None:
    try:
        plot(results, str(path))
    except OSError as error:
        Path(path).unlink(missing_ok=True)
        raise UsageError(f"--plot {path}: cannot write: {error.strerror}") from None


# One colour and marker per integrator or peer, the same in every plot and every run.
# MuJoCo's lines are dashed; our tolerance sweeps thick; the scene as set a black star.
SERIES_STYLE = {
    "euler": ("#393b79", "x"), "semi_implicit_euler": ("#ff7f0e", "s"),
    "midpoint": ("#7f7f7f", "^"), "rk4": ("#1f77b4", "o"), "rk38": ("#bcbd22", "v"),
    "dopri5": ("#2ca02c", "D"),
    "rk4 + tolerance": ("crimson", "s"), "rk38 + tolerance": ("#8b4513", "P"),
    "mujoco Euler": ("#e377c2", "<"), "mujoco implicit": ("#9467bd", ">"),
    "mujoco implicitfast": ("#8c564b", "h"), "mujoco RK4": ("#17becf", "d"),
}
SPARE_STYLES = [("#637939", "p"), ("#ad494a", "*"), ("#3182bd", "X"), ("#756bb1", "H")]
TARGET_LINE = {"color": "grey", "linestyle": ":", "linewidth": 1.2}
FLOOR_LINE = {"color": "#555555", "linestyle": "-.", "linewidth": 1.5}
TARGET_LABEL = f"{TARGET:g}: the price list's target"
FLOOR_LABEL = "MuJoCo's error floor (soft constraints)"
LEGEND_COLUMN_INCHES = 4.2       # one legend column at fontsize 8 holds the longest label
LABEL_SPACING = (0.3, 0.45)      # decades in x and y between two tolerance labels


def plot(results, path: str) -> None:
    """Work-precision diagram: max state error against CPU time, log-log, one panel per
    scene; ours solid, MuJoCo dashed, the tolerance sweep and the scene as set marked.
    Constrained layout with the legend outside the panels and a tight bounding box: the
    title, every panel and the whole legend fit at any number of scenes."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns = min(MAX_COLUMNS, len(results))
    rows = ceil(len(results) / columns)
    width = PANEL_SIZE[0] * columns
    peers = any(r["kind"] == "mujoco" for result in results for r in result["runs"])
    title = textwrap.fill("What accuracy costs: max state error vs CPU time, "
                          + ("ours and MuJoCo on the same scenes" if peers else "our integrators"),
                          width=int(width * 72 / (12 * 0.55)))
    entries = len(legend_labels(results))
    ncols = max(1, min(entries, int(width // LEGEND_COLUMN_INCHES)))
    # the figure grows by what the title and the legend need: the panels keep their size
    height = (PANEL_SIZE[1] * rows + 0.25 * (title.count("\n") + 1) + 0.3
              + 0.19 * ceil(entries / ncols))
    fig, axes = plt.subplots(rows, columns, squeeze=False, dpi=100, layout="constrained",
                             figsize=(width, height))
    for ax, result in zip(axes.flat, results):
        panel(ax, result)
    for ax in list(axes.flat)[len(results):]:
        ax.axis("off")
    handles = {}
    for ax in axes.flat:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, handle)
    fig.legend(list(handles.values()), list(handles), loc="outside lower center", fontsize=8,
               ncols=ncols, frameon=False)
    fig.suptitle(title, fontsize=12)
    fig.savefig(path, bbox_inches="tight", pad_inches=0.15)
    plt.close(fig)


def legend_labels(results) -> list:
    """Every legend entry the panels will draw, in order: lines, then the guide lines."""
    labels = {}
    for result in results:
        for name in dict.fromkeys(r["series"] for r in result["runs"]):
            runs = [r for r in result["runs"] if r["series"] == name
                    and isfinite(r["max_state_error"]) and r["max_state_error"] > 0]
            if runs:
                labels.setdefault(_label(name, runs[0]))
    if any(result["peers"].get("mujoco", {}).get("floor") for result in results):
        labels.setdefault(FLOOR_LABEL)
    return list(labels) + [TARGET_LABEL]


def _style(name: str, kind: str) -> dict:
    if kind == "as set":
        return {"linestyle": "none", "marker": "*", "markersize": 13, "color": "black"}
    color, marker = SERIES_STYLE.get(name) or SPARE_STYLES[zlib.crc32(name.encode())
                                                            % len(SPARE_STYLES)]
    if kind == "mujoco":
        return {"linestyle": "--", "marker": marker, "markersize": 4, "linewidth": 1.2,
                "alpha": 0.85, "color": color}
    if kind == "tolerance":
        return {"linestyle": "-", "marker": marker, "markersize": 5, "linewidth": 2.2,
                "color": color}
    return {"linestyle": "-", "marker": marker, "markersize": 4, "linewidth": 1.4,
            "color": color}


def _label(name: str, run: dict) -> str:
    if run["kind"] == "mujoco":
        return f"MuJoCo {name[7:]}, h sweep (mj_step)"
    if run["kind"] == "as set":
        return "ours as set: scene's h and tolerance (Simulator.step)"
    if run["kind"] == "tolerance":
        return f"ours {name} sweep, scene's h (Simulator.step)"
    if run["tolerance"] is not None:
        return f"ours {name}, rtol = atol sweep"
    return f"ours {name}, h sweep"


def panel(ax, result: dict) -> None:
    labelled = []                     # (log10 x, log10 y) of the tolerance labels so far
    # the rightmost point's label goes left of it: right of it, it ran past the panel's edge
    rightmost = max((r["cpu_s_per_sim_s"] for r in result["runs"]
                     if isfinite(r["max_state_error"]) and r["max_state_error"] > 0), default=0)
    for name in dict.fromkeys(r["series"] for r in result["runs"]):
        runs = [r for r in result["runs"] if r["series"] == name
                and isfinite(r["max_state_error"]) and r["max_state_error"] > 0]
        if not runs:
            continue
        style = _style(name, runs[0]["kind"])
        ax.loglog([r["cpu_s_per_sim_s"] * 1e6 for r in runs],
                  [r["max_state_error"] for r in runs], label=_label(name, runs[0]), **style)
        if runs[0]["kind"] == "tolerance":          # which tolerance each point is
            for r in runs:
                x, y = r["cpu_s_per_sim_s"] * 1e6, r["max_state_error"]
                if _crowded(labelled, log10(x), log10(y)):
                    continue
                labelled.append((log10(x), log10(y)))
                last = r["cpu_s_per_sim_s"] >= rightmost
                ax.annotate(f"{r['tolerance']:g}", (x, y), fontsize=6.5, color=style["color"],
                            textcoords="offset points", xytext=(-4, -3) if last else (4, 2),
                            ha="right" if last else "left", va="top" if last else "baseline")
    floor = result["peers"].get("mujoco", {}).get("floor")
    if floor:
        ax.axhline(floor, label=FLOOR_LABEL, **FLOOR_LINE)
    ax.axhline(TARGET, label=TARGET_LABEL, **TARGET_LINE)
    ax.set_xlabel("CPU µs per simulated second (lower is cheaper)")
    ax.set_ylabel("max |state error| (rad, rad/s)")
    ax.set_title(f"{result['scene']} ({result['duration']:g} s)", fontsize=10)
    ax.grid(True, which="major", alpha=0.4)


def _crowded(labelled, x: float, y: float) -> bool:
    return any(abs(x - lx) < LABEL_SPACING[0] and abs(y - ly) < LABEL_SPACING[1]
               for lx, ly in labelled)
