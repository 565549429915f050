"""The picture beside a sweep's table (OUT.png): a heat map where two grid keys are numbers
(one panel per value of the other grid keys; the median over a grid point's draws), with
the samples that did not end ok marked, and the stability planner's bound drawn where one
axis is step_size; else histograms of the figures (Monte Carlo), or a figure against the
one grid key.
"""
from __future__ import annotations

from itertools import product

import numpy as np

from ...physics.effects import scene_effects
from ...physics.scene import SceneError
from ...usage import did_you_mean
from ...physics.stepping import stability
from ...physics.stepping.integrators import INTEGRATORS
from .plan import overrides
from .table import PICTURE, beside

REFERENCE_FIGURES = ("settle_time", "overshoot", "steady_state_error")
MAX_PANELS = 6
NOT_OK = {"diverged": "#222222", "fault": "#8b0000", "refused": "#bbbbbb"}


def check_plot(plot, header) -> list:
    """--plot's columns, each one of the table's (`header`), or one line saying which not."""
    if plot is None:
        return []
    names = [n.strip() for n in plot.split(",") if n.strip()]
    unknown = [n for n in names if n not in header] or ([] if names else [plot])
    if unknown:
        raise SceneError(f"--plot {plot}: no column {unknown[0]!r}; "
                         f"{did_you_mean(unknown[0], header)}columns: {', '.join(header)}")
    return names


def shown(columns: dict, plot) -> list:
    """The columns the picture shows: --plot's, else the reference figures where any row
    has them, else max_abs_residual."""
    figures = [f"{name}_{joint}" for name in REFERENCE_FIGURES for joint in (1, 2)
               if np.isfinite(columns.get(f"{name}_{joint}", np.array([np.nan]))).any()]
    return check_plot(plot, list(columns)) or figures or ["max_abs_residual"]


def draw(out, sweep, columns: dict, plot=None):
    """Write the picture beside `out`; returns its path."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = shown(columns, plot)
    numeric = [v for v in sweep.plan.grid if len(v.values) > 1 and len(v.columns) == 1
               and all(isinstance(x, (int, float)) for x in v.values)]
    if len(numeric) >= 2:
        figure = heat_maps(plt, sweep, columns, names[0], numeric)
    elif sweep.plan.draws > 1 or not numeric:
        figure = distributions(plt, sweep, columns, names)
    else:
        figure = against(plt, columns, names, numeric[0])
    path = beside(out, PICTURE)
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def heat_maps(plt, sweep, columns, name: str, numeric):
    x_key, y_key = _axes(numeric)
    others = [v for v in sweep.plan.grid if v not in (x_key, y_key)]
    panels = list(product(*(v.values for v in others)))[:MAX_PANELS]
    figure, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels) + 1, 4.6),
                                squeeze=False, constrained_layout=True)
    values, status = columns[name], columns["status"]
    colour = _norm(values[np.array([s == "ok" for s in status], dtype=bool)])
    for ax, at in zip(axes[0], panels):
        keep = np.ones(len(values), bool)
        for v, value in zip(others, at):
            keep &= _matches(columns, v, value)
        grid = np.full((len(y_key.values), len(x_key.values)), np.nan)
        bad = np.full(grid.shape, "", dtype=object)
        for i, y in enumerate(y_key.values):
            for j, x in enumerate(x_key.values):
                cell = keep & (columns[x_key.key] == x) & (columns[y_key.key] == y)
                outcomes = [status[k] for k in np.flatnonzero(cell)]
                worst = [s for s in NOT_OK if s in outcomes]
                bad[i, j] = worst[0] if worst else ""
                good = values[cell][[s == "ok" for s in outcomes]]
                grid[i, j] = np.median(good[np.isfinite(good)]) if np.isfinite(good).any() \
                    else np.nan
        xs, ys = _edges(x_key.values), _edges(y_key.values)
        mesh = ax.pcolormesh(xs, ys, grid, norm=colour, cmap="viridis")
        for kind, shade in NOT_OK.items():
            mask = np.where(bad == kind, 1.0, np.nan)
            if np.isfinite(mask).any():
                ax.pcolormesh(xs, ys, mask, cmap=_flat(shade), vmin=0, vmax=1)
                ax.plot([], [], "s", color=shade, label=kind)
        _planner(ax, sweep, x_key, y_key, others, at)
        _scale(ax, x_key, y_key)
        ax.set_xlabel(x_key.key)
        ax.set_ylabel(y_key.key)
        ax.set_title(", ".join(f"{v.key} = {_text(value)}" for v, value in zip(others, at))
                     or sweep.base.name, fontsize=10)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="lower left", fontsize=8, framealpha=0.85)
    figure.colorbar(mesh, ax=axes[0].tolist(), label=name + (" (median of the draws ok)"
                                                             if sweep.plan.draws > 1 else ""))
    return figure


def distributions(plt, sweep, columns, names):
    """Empirical CDFs of each figure shown, of the samples that ended ok: a colour per grid
    point (up to MAX_PANELS), a line style per joint."""
    figures = list(dict.fromkeys(n[:-2] if n[-2:] in ("_1", "_2") else n for n in names))
    figure, axes = plt.subplots(1, len(figures), figsize=(4.8 * len(figures), 4.0),
                                squeeze=False, constrained_layout=True)
    ok = np.array([s == "ok" for s in columns["status"]], dtype=bool)
    point = columns["index"].astype(int) // sweep.plan.draws
    shown_points = sorted(set(point.tolist()))[:MAX_PANELS]
    for ax, figure_name in zip(axes[0], figures):
        for p, colour in zip(shown_points, plt.rcParams["axes.prop_cycle"].by_key()["color"]):
            for column in [n for n in names if n == figure_name or n[:-2] == figure_name]:
                values = np.sort(columns[column][ok & (point == p)])
                values = values[np.isfinite(values)]
                if not len(values):
                    continue
                style = "--" if column.endswith("_2") else "-"
                joint = column[-1:] if column != figure_name else ""
                ax.step(values, np.arange(1, len(values) + 1) / len(values), where="post",
                        color=colour, linestyle=style, label=_point_label(sweep, p) + joint)
        ax.set_xlabel(figure_name + _unit(figure_name))
        ax.set_ylabel("fraction of samples at or below")
        ax.set_ylim(0, 1.02)
        ax.legend(fontsize=7)
    figure.suptitle(f"{int(ok.sum())} of {len(ok)} samples ok; solid: joint 1, dashed: joint 2"
                    if any(n.endswith("_2") for n in names) else
                    f"{int(ok.sum())} of {len(ok)} samples ok", fontsize=10)
    return figure


def _point_label(sweep, point: int) -> str:
    """The grid point's values, e.g. `command_delay = 0.002, joint `."""
    values = sweep.plan.values(point * sweep.plan.draws)
    grid = [f"{v.key} = {_text(x)}" for v, x in zip(sweep.plan.varies, values) if not v.drawn]
    return (", ".join(grid) + ", joint ") if grid else "joint "


def _unit(figure_name: str) -> str:
    from .summary import UNITS
    return f" ({UNITS[figure_name]})" if figure_name in UNITS else ""


def against(plt, columns, names, key):
    """Each figure shown against the one grid key: a panel per figure, both joints."""
    figures = list(dict.fromkeys(n[:-2] if n[-2:] in ("_1", "_2") else n for n in names))
    figure, axes = plt.subplots(1, len(figures), figsize=(4.6 * len(figures), 3.8),
                                squeeze=False, constrained_layout=True)
    for ax, figure_name in zip(axes[0], figures):
        for column in [n for n in names if n == figure_name or n[:-2] == figure_name]:
            style = "s--" if column.endswith("_2") else "o-"
            ax.plot(columns[key.key], columns[column], style, label=column)
        _scale(ax, key, None)
        ax.set_xlabel(key.key)
        ax.set_ylabel(figure_name + _unit(figure_name))
        ax.legend(fontsize=8)
    return figure


def _axes(numeric):
    """(x, y) of the heat map: step_size across where it is varied, else the first two."""
    steps = [v for v in numeric if v.field == "step_size"]
    x = steps[0] if steps else numeric[0]
    y = next(v for v in numeric if v is not x)
    return x, y


def _matches(columns, v, value):
    if len(v.columns) == 1:
        return np.asarray(columns[v.key], dtype=object) == value
    return np.all([np.asarray(columns[c]) == x for c, x in zip(v.columns, value)], axis=0)


def _planner(ax, sweep, x_key, y_key, others, at) -> None:
    """The largest step the stability planner takes whole (no sub-steps: every stiff
    effect's eigenvalues inside the method's stability region, at any pose), for each value
    along the other axis: its bound, drawn over the map."""
    if "step_size" not in (x_key.field, y_key.field):
        return
    h_key, k_key = (x_key, y_key) if x_key.field == "step_size" else (y_key, x_key)
    low, high = min(h_key.values) / 100, max(h_key.values) * 100
    found = []
    for k in k_key.values:
        try:
            scene = sweep.base.replace(**overrides(sweep.base, [k_key, *others], [k, *at]))
        except SceneError:
            continue
        found.append((largest_whole_step(scene, low, high), k))
    points = [(h, k) for h, k in found if h is not None]
    if points:
        h, k = zip(*points)
        ax.plot(*((h, k) if h_key is x_key else (k, h)), "w--", linewidth=2,
                label="planner's stability bound")
        ax.set_xlim(*_edges(x_key.values)[[0, -1]])
        ax.set_ylim(*_edges(y_key.values)[[0, -1]])


def largest_whole_step(scene, low: float, high: float):
    """The largest h in [low, high] the planner takes without sub-steps (bisected in log
    h, to 0.1 %); None where even `low` needs them or `high` does not."""
    effects, arm = scene_effects(scene), scene.arm
    tableau = INTEGRATORS[scene.method]

    def whole(h):
        return stability.planned(tableau, effects, arm, h)[2] == 1

    if not whole(low) or whole(high):
        return None
    for _ in range(60):
        if high / low < 1.001:
            break
        middle = (low * high) ** 0.5
        low, high = (middle, high) if whole(middle) else (low, middle)
    return low


def _edges(values) -> np.ndarray:
    """Cell edges around grid values: geometric midpoints on a log grid."""
    v = np.asarray(values, dtype=float)
    if len(v) < 2:
        return np.array([v[0] - 0.5, v[0] + 0.5])
    if _is_log(v):
        mid = np.sqrt(v[1:] * v[:-1])
        return np.concatenate([[v[0] ** 2 / mid[0]], mid, [v[-1] ** 2 / mid[-1]]])
    mid = (v[1:] + v[:-1]) / 2
    low = 2 * v[0] - mid[0]
    if v.min() > 0 and low <= 0:            # positive values: no cell reaches below 0
        low = v[0] / 2
    return np.concatenate([[low], mid, [2 * v[-1] - mid[-1]]])


def _is_log(v) -> bool:
    """Values drawn on a log axis: all positive, and spanning 20x or more, or evenly
    spaced in log (a log: grid), or two of them 4x apart."""
    v = np.sort(np.asarray(v, dtype=float))
    if len(v) < 2 or not np.all(v > 0):
        return False
    ratios = v[1:] / v[:-1]
    return bool(v[-1] >= 20 * v[0] or (len(v) == 2 and ratios[0] >= 4)
                or (len(v) > 2 and np.ptp(np.log(ratios)) < 1e-9 and ratios[0] > 1.5))


def _scale(ax, x_key, y_key) -> None:
    if _is_log(x_key.values):
        ax.set_xscale("log")
    if y_key is not None and _is_log(y_key.values):
        ax.set_yscale("log")


def _norm(values):
    from matplotlib.colors import LogNorm, Normalize
    finite = values[np.isfinite(values)]
    positive = finite[finite > 0]
    if len(positive) == len(finite) and len(positive) and positive.max() > 100 * positive.min():
        return LogNorm(positive.min(), positive.max())
    return Normalize(*(finite.min(), finite.max()) if len(finite) else (0, 1))


def _flat(shade):
    from matplotlib.colors import ListedColormap
    return ListedColormap([shade])


def _text(value) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)
