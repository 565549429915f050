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


SHORT_PATHS = {"compiled (numba)": "compiled", "mj_step from Python": "mj_step",
               "mujoco.rollout": "rollout"}


def paths_said(result: dict) -> str:
    """How ours ran: the scene's path (the user's), and the series that ran on another."""
    others = {}
    for r in result["runs"]:
        if r["estimate"] is not None and r["path"] != result["path"]:
            others.setdefault(r["path"], []).append(r["integrator"])
    return result["path"] + "".join(f"; {', '.join(dict.fromkeys(names))}: {path}"
                                    for path, names in others.items())


def format_table(result: dict) -> str:
    header = (f"{'method':<34} {'estimate':>8} {'path':>8} {'h (s)':>9} {'tol':>7} "
              f"{'max |state err|':>15} {'energy drift J':>14} {'residual J':>10} "
              f"{'sub-steps':>9} {'CPU s/sim s':>11}")
    lines = [f"scene {result['scene']}, {result['duration']:g} s, compared every "
             f"{result['sample_interval']:g} s with {result['reference']}",
             f"ours: Simulator.run over the whole run, path {paths_said(result)}; the node's "
             "path: Simulator.step, a Python call per step", header, "-" * len(header)]
    for r in result["runs"] + [result["node"]]:
        tol = "" if r["tolerance"] is None else f"{r['tolerance']:.0e}"
        lines.append(f"{r['series']:<34} {r['estimate'] or '':>8} "
                     f"{SHORT_PATHS.get(r['path'], r['path']):>8} {r['step_size']:>9g} {tol:>7} "
                     f"{r['max_state_error']:>15.3e} {_number(r['energy_drift'], '.3e', 14)} "
                     f"{_number(r['balance_residual'], '.2e', 10)} "
                     f"{_number(r['substeps'], 'd', 9)} {r['cpu_s_per_sim_s']:>11.2e}")
    lines.append("")
    for name, o in result["orders"].items():
        fitted = "n/a (too few points in range)" if o["fitted"] is None else f"{o['fitted']:.2f}"
        lines.append(f"fitted order {name:<20} {fitted}  (theory {o['theory']})")
    mujoco = result["peers"].get("mujoco", {})
    if "version" in mujoco:
        lines.append(f"MuJoCo {mujoco['version']}: mj_step, one Python call per step, and "
                     "mujoco.rollout, every step in one call"
                     + "".join(f"; {note}" for note in mujoco["notes"]))
    if "floor" in mujoco:
        lines.append(f"MuJoCo's error floor here: {mujoco['floor']:.2e} (its soft constraints "
                     "follow their own law: the error stops falling with h)")
    lines += result["notes"]
    for label, runs in (("ours with the estimate", ours(result, "global")),
                        ("ours without", ours(result, "off")),
                        ("MuJoCo", [r for r in result["runs"] if r["estimate"] is None])):
        best = cheapest(result, TARGET, runs)
        if best:
            lines.append(f"cheapest run with max state error <= {TARGET:g}, {label}: "
                         f"{best['series']} {what(best)} "
                         f"({best['cpu_s_per_sim_s']:.2e} CPU s per simulated s)")
    return "\n".join(lines)


def ours(result: dict, estimate: str) -> list:
    return [r for r in result["runs"] if r["estimate"] == estimate]


def what(run: dict) -> str:
    return f"h={run['step_size']:g}" + (f" tol={run['tolerance']:g}" if run["tolerance"] else "")


def cheapest(result: dict, target: float, runs=None):
    """The run reaching max state error <= target at the least CPU time, or None."""
    good = [r for r in (result["runs"] if runs is None else runs)
            if r["max_state_error"] <= target]
    return min(good, key=lambda r: r["cpu_s_per_sim_s"], default=None)


def pick(result: dict, target: float, runs: list) -> dict | None:
    """Of `runs`: the cheapest at least `target` accurate, else the most accurate one (None
    if none ran)."""
    return cheapest(result, target, runs) or min(runs, key=lambda r: r["max_state_error"],
                                                 default=None)


def price_columns(result: dict, target: float) -> list:
    """(label, run) per line of the price list for one scene (MuJoCo's where it ran)."""
    runs = result["runs"]
    as_set = next((r for r in runs if r["kind"] == "as set"), None)
    at_h = as_set["step_size"] if as_set else None

    def mujoco(kind, h=None):
        return [r for r in runs if r["kind"] == kind and h in (None, r["step_size"])]
    theirs = [] if not mujoco("mujoco") else [
        ("MuJoCo best at h, mj_step", min(mujoco("mujoco", at_h), default=None,
                                          key=lambda r: r["max_state_error"])),
        ("MuJoCo best at h, rollout", min(mujoco("mujoco rollout", at_h), default=None,
                                          key=lambda r: r["max_state_error"])),
        ("MuJoCo, mj_step", pick(result, target, mujoco("mujoco"))),
        ("MuJoCo, rollout", pick(result, target, mujoco("mujoco rollout")))]
    return [("ours as set", as_set),
            ("ours as set, the node's path", result.get("node")),
            ("ours rk4 + tolerance", pick(result, target, [
                r for r in runs if r["kind"] == "tolerance" and r["integrator"] == "rk4"])),
            ("ours, estimate global", pick(result, target, ours(result, "global"))),
            ("ours, estimate off", pick(result, target, ours(result, "off")))] + theirs


def price_list(results: list, target: float) -> str:
    """Per scene and line: error, µs per simulated second and which run it is."""
    lines = [f"price list: max |state error| and CPU µs per simulated second; per line the "
             f"cheapest run reaching {target:g}, else its most accurate (the scene as set: "
             "Simulator.run; the node's path: Simulator.step; MuJoCo best at h: its most "
             "accurate integrator at the scene's h)", ""]
    for result in results:
        lines.append(f"{result['scene']}:")
        for label, run in price_columns(result, target):
            if run is None:
                lines.append(f"  {label:<30} —")
                continue
            lines.append(f"  {label:<30} {run['max_state_error']:>9.1e} "
                         f"{run['cpu_s_per_sim_s'] * 1e6:>10.0f} µs/s  {run['series']} "
                         f"{what(run)}")
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
# Ours solid with the error estimate, dotted and hollow without; MuJoCo dashed through mj_step,
# dash-dotted and hollow through mujoco.rollout; our tolerance sweeps thick; the scene as set a
# black star.
SERIES_STYLE = {
    "euler": ("#393b79", "x"), "semi_implicit_euler": ("#ff7f0e", "s"),
    "midpoint": ("#7f7f7f", "^"), "rk4": ("#1f77b4", "o"), "rk38": ("#bcbd22", "v"),
    "dopri5": ("#2ca02c", "D"), "exponential_rk4": ("#17a589", "8"),
    "rk4 + tolerance": ("crimson", "s"), "rk38 + tolerance": ("#8b4513", "P"),
    "exponential_rk4 + tolerance": ("#c0392b", "X"),
    "mujoco Euler": ("#e377c2", "<"), "mujoco implicit": ("#9467bd", ">"),
    "mujoco implicitfast": ("#8c564b", "h"), "mujoco RK4": ("#17becf", "d"),
}
SPARE_STYLES = [("#637939", "p"), ("#ad494a", "*"), ("#3182bd", "X"), ("#756bb1", "H")]
TARGET_LINE = {"color": "grey", "linestyle": ":", "linewidth": 1.2}
FLOOR_LINE = {"color": "#555555", "linestyle": (0, (8, 2, 1, 2)), "linewidth": 1.5}
TARGET_LABEL = f"{TARGET:g}: the price list's target"
FLOOR_LABEL = "MuJoCo's error floor (soft constraints)"
LEGEND_COLUMN_INCHES = 4.2       # one legend column at fontsize 8 holds the longest label
LABEL_SPACING = (0.3, 0.45)      # decades in x and y between two tolerance labels
LABEL_ROOM = (0.9, 0.95)         # past these fractions of a panel a label goes left, below
MUJOCO_KINDS = ("mujoco", "mujoco rollout")


def title_of(results) -> str:
    peers = any(r["kind"] in MUJOCO_KINDS for result in results for r in result["runs"])
    return ("What accuracy costs: max state error vs CPU time, "
            + ("ours and MuJoCo on the same scenes" if peers else "ours"))


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
    title = textwrap.fill(title_of(results), width=int(width * 72 / (12 * 0.55)))
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
                labels.setdefault(_label(name, runs[0], result["path"]))
    if any(result["peers"].get("mujoco", {}).get("floor") for result in results):
        labels.setdefault(FLOOR_LABEL)
    return list(labels) + [TARGET_LABEL]


def _style(name: str, kind: str, estimate: str | None = "global") -> dict:
    if kind == "as set":
        return {"linestyle": "none", "marker": "*", "markersize": 13, "color": "black"}
    key = name.removesuffix(", estimate off").removesuffix(" rollout")
    color, marker = SERIES_STYLE.get(key) or SPARE_STYLES[zlib.crc32(key.encode())
                                                           % len(SPARE_STYLES)]
    hollow = {"markerfacecolor": "white"} if kind == "mujoco rollout" or estimate == "off" else {}
    if kind in MUJOCO_KINDS:
        return {"linestyle": "--" if kind == "mujoco" else "-.", "marker": marker,
                "markersize": 4, "linewidth": 1.2, "alpha": 0.85, "color": color, **hollow}
    if kind == "tolerance":
        return {"linestyle": "-", "marker": marker, "markersize": 5, "linewidth": 2.2,
                "color": color}
    return {"linestyle": ":" if estimate == "off" else "-", "marker": marker, "markersize": 4,
            "linewidth": 1.4, "color": color, **hollow}


def _label(name: str, run: dict, path: str = "") -> str:
    """The legend's words for a series; ours on another path than the panel's says which."""
    if run["kind"] == "mujoco":
        return f"MuJoCo {name[7:]}, h sweep (mj_step from Python)"
    if run["kind"] == "mujoco rollout":
        return f"MuJoCo {name[7:].removesuffix(' rollout')}, h sweep (mujoco.rollout)"
    if run["kind"] == "as set":
        return "ours as set: scene's h and tolerance"
    if run["kind"] == "tolerance":
        return f"ours {name} sweep, scene's h"
    sweep = "rtol = atol sweep" if run["tolerance"] is not None else "h sweep"
    other = f" ({run['path']})" if path and run["path"] != path else ""
    return f"ours {run['integrator']}, {sweep}, estimate {run['estimate']}{other}"


def panel(ax, result: dict) -> None:
    labels = []                       # (x, y, tolerance, colour) of the tolerance points
    for name in dict.fromkeys(r["series"] for r in result["runs"]):
        runs = [r for r in result["runs"] if r["series"] == name
                and isfinite(r["max_state_error"]) and r["max_state_error"] > 0]
        if not runs:
            continue
        style = _style(name, runs[0]["kind"], runs[0]["estimate"])
        ax.loglog([r["cpu_s_per_sim_s"] * 1e6 for r in runs], [r["max_state_error"] for r in runs],
                  label=_label(name, runs[0], result["path"]), **style)
        if runs[0]["kind"] == "tolerance":          # which tolerance each point is
            labels += [(r["cpu_s_per_sim_s"] * 1e6, r["max_state_error"], r["tolerance"],
                        style["color"]) for r in runs]
    floor = result["peers"].get("mujoco", {}).get("floor")
    if floor:
        ax.axhline(floor, label=FLOOR_LABEL, **FLOOR_LINE)
    ax.axhline(TARGET, label=TARGET_LABEL, **TARGET_LINE)
    label_tolerances(ax, labels)
    decades(ax)
    ax.set_xlabel("CPU µs per simulated second (lower is cheaper)")
    ax.set_ylabel("max |state error| (rad, rad/s)")
    ax.set_title(f"{result['scene']} ({result['duration']:g} s; ours: Simulator.run, "
                 f"{result['path']})", fontsize=10)
    ax.grid(True, which="major", alpha=0.4)


def label_tolerances(ax, labels) -> None:
    """Each tolerance beside its point, where no other label is near; to its left near the
    panel's right edge and below it near the top, so that it stays inside the panel."""
    placed = []                       # (log10 x, log10 y) of the labels so far
    ax.get_xlim(), ax.get_ylim()      # the limits autoscaled from every line now
    to_panel = ax.transScale + ax.transLimits       # data -> fractions of the panel (limits set)
    for x, y, tolerance, color in labels:
        if _crowded(placed, log10(x), log10(y)):
            continue
        placed.append((log10(x), log10(y)))
        fx, fy = to_panel.transform((x, y))
        left, below = fx > LABEL_ROOM[0], fy > LABEL_ROOM[1]
        ax.annotate(f"{tolerance:g}", (x, y), fontsize=6.5, color=color,
                    textcoords="offset points", xytext=(-4 if left else 4, -2 if below else 2),
                    ha="right" if left else "left", va="top" if below else "bottom")


def decades(ax) -> None:
    """Only the decades labelled on an axis that spans one or more (matplotlib labels some
    minor ticks too up to about two, and they ran into each other)."""
    from matplotlib.ticker import NullFormatter
    for axis, (low, high) in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
        if high >= 10 * low:
            axis.set_minor_formatter(NullFormatter())


def _crowded(labelled, x: float, y: float) -> bool:
    return any(abs(x - lx) < LABEL_SPACING[0] and abs(y - ly) < LABEL_SPACING[1]
               for lx, ly in labelled)
