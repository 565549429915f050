"""What a sweep prints when it ends: how the samples came out, the spread of every figure,
and what it cost (the wall time the table leaves out)."""
from __future__ import annotations

import numpy as np

from .rows import OUTCOMES

UNITS = {"peak_torque": "N m", "overshoot": "rad", "settle_time": "s", "tracking_error": "rad",
         "steady_state_error": "rad", "max_abs_residual": "J", "accumulated_error": "rad"}
QUANTILES = (0.0, 0.05, 0.5, 0.95, 1.0)


def describe(sweep, result, out=None, picture=None) -> str:
    plan = sweep.plan
    lines = [f"sweep {sweep.base.name}: {plan.count} samples ({plan.shape_text}), "
             f"{sweep.duration:g} s each, h = {_step_sizes(sweep)}, estimate {sweep.base.estimate}",
             "outcomes: " + ", ".join(f"{name} {result.counts[name]}" for name in OUTCOMES)
             + (f" (of {len(result.columns.get('index', []))} samples in the table)"
                if not result.complete else "")]
    rows = [(name, UNITS[_figure(name)], result.columns[name]) for name in result.columns
            if _figure(name) in UNITS and np.isfinite(result.columns[name]).any()]
    if rows:
        width = max(len(f"{name} ({unit})") for name, unit, _ in rows)
        lines.append(f"{'':{width}}  " + "".join(f"{label:>11}" for label in
                                                 ("min", "5 %", "median", "95 %", "max", "n")))
        for name, unit, values in rows:
            finite = values[np.isfinite(values)]
            cells = "".join(f"{v:11.4g}" for v in np.quantile(finite, QUANTILES))
            lines.append(f"{f'{name} ({unit})':{width}}  {cells}{len(finite):11d}")
    rate = result.ran / result.seconds if result.seconds > 0 else float("nan")
    lines.append(f"{result.ran} samples run in {result.seconds:.3g} s on {result.workers}: "
                 f"{rate:.4g} samples/s; compiling kernels took {result.compiling:.3g} s of "
                 "the workers' time")
    if out is not None:
        lines.append(f"table {out} ({len(result.columns.get('index', []))} rows); timing "
                     f"{out.with_suffix('.json')}" + (f"; picture {picture}" if picture else ""))
    return "\n".join(lines)


def _figure(column: str) -> str:
    """The figure a column holds: settle_time_1 -> settle_time."""
    base, _, joint = column.rpartition("_")
    return base if joint in ("1", "2") and base in UNITS else column


def _step_sizes(sweep) -> str:
    varied = [v for v in sweep.plan.varies if v.field == "step_size"]
    return "varied" if varied else f"{sweep.base.step_size:g} s"
