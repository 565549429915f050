"""What accuracy costs: a work-precision study of every integrator on any scene.

Each method runs the scene at several step sizes (embedded pairs: several tolerances at
the scene's publish step) and is compared with a high-accuracy reference, scipy's DOP853
at rtol = atol = 1e-13, at the same physical times. The reference is built from
`model.forward_dynamics`, not from the generated right-hand side, so it also checks that
code. Reported per run: max state error, energy drift, balance residual, right-hand-side
evaluations and CPU seconds per simulated second; per fixed-step method, the fitted
convergence order.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from math import isfinite, log
from pathlib import Path

from ..physics import model
from ..physics.integrators import INTEGRATORS, compile_step
from ..physics.scene import Scene, SceneError
from ..physics.simulator import Simulator
from ..outputs import check_output, clear_output, strict_json, write_text
from ..usage import UsageError
from .arguments import add_scene_arguments, scene_from_args
from .progress import Progress

REFERENCE_TOLERANCE = 1e-13
MODEL_EFFECTS = {"gravity", "damping", "actuator"}    # what model.forward_dynamics covers
MAX_RUN_STEPS = 10_000_000      # steps per run; beyond, a study would run for hours
PLOT_FORMATS = (".png", ".svg", ".pdf")
DEFAULT_STEPS = (0.02, 0.01, 0.005, 0.0025, 0.00125, 0.000625, 0.0003125, 0.00015625)
DEFAULT_TOLERANCES = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)
# Errors used to fit an order: below, the reference and round-off dominate; above, the
# method is not yet in its asymptotic regime.
ORDER_FIT_RANGE = (1e-11, 0.3)
MIN_TOLERANCE = 1e-14
MIN_TIMED_CPU_S = 0.05          # repeat short runs until this much CPU time, keep the fastest


@dataclass
class Run:
    integrator: str
    step_size: float
    tolerance: float | None       # None for fixed-step methods
    max_state_error: float        # max over sample times and q1, q2, qd1, qd2 of |y - y_ref|
    energy_drift: float           # max over sample times of |E - E_ref| (J)
    balance_residual: float       # max over every step of |E - E(0) - W + dissipated| (J)
    rhs_evaluations: int
    cpu_s_per_sim_s: float


def sample_times(scene: Scene, duration: float, interval: float) -> list[float]:
    count = scene.steps_for(duration, interval)
    return [k * interval for k in range(count + 1)]


def reference(scene: Scene, times) -> list[tuple]:
    """(q1, q2, qd1, qd2, *channels) at `times` from scipy's DOP853 at rtol = atol = 1e-13."""
    import numpy as np
    from scipy.integrate import solve_ivp

    sim = Simulator(scene)
    arm, gravity, damping = scene.arm, scene.gravity, scene.damping
    torque_of = sim.dynamics.applied_torque
    channels = sim.channels

    def rates(t, y):
        q, qd = (y[0], y[1]), (y[2], y[3])
        tau = torque_of(q)
        qdd = model.forward_dynamics(arm, q, qd, tau, gravity, damping)
        books = {"work": tau[0] * qd[0] + tau[1] * qd[1],
                 "dissipated": damping * (qd[0] * qd[0] + qd[1] * qd[1])}
        return [qd[0], qd[1], qdd[0], qdd[1], *(books[c] for c in channels)]

    if not set(sim.dynamics.effects) <= MODEL_EFFECTS or not isinstance(damping, float):
        # The model's equations cover the explainer's effects; the others are checked
        # against separately written equations in test/test_effects.py, so here the
        # reference integrates the generated right-hand side (integration error only).
        f = sim.dynamics.function
        width = 4 + len(sim.extra)          # f takes q, q̇ and the extra states, not channels
        rates = lambda t, y: (y[2], y[3], *f(*y[:width]))  # noqa: E731  (f gives the rest)

    solution = solve_ivp(rates, (times[0], times[-1]), list(sim.state), method="DOP853",
                         t_eval=times, rtol=REFERENCE_TOLERANCE, atol=REFERENCE_TOLERANCE)
    if not solution.success:
        raise SceneError(f"the reference integration failed: {solution.message}")
    return [tuple(row) for row in np.asarray(solution.y).T]


class _Counted:
    """f with a call counter (used only in the untimed pass)."""

    def __init__(self, f):
        self.f, self.calls = f, 0

    def __call__(self, *y):
        self.calls += 1
        return self.f(*y)


def measure(scene: Scene, name: str, step_size: float, tolerance: float | None, times,
            ref) -> Run:
    """One method at one step size (or tolerance) against the reference samples."""
    sim = Simulator(scene.replace(integrator=name, step_size=step_size))
    tolerances = {} if tolerance is None else {"rtol": tolerance, "atol": tolerance}
    step = compile_step(INTEGRATORS[name], len(sim.channels), extra=len(sim.extra), **tolerances)
    every = scene.steps_for(times[1] - times[0], step_size) if len(times) > 1 else 1
    total = every * (len(times) - 1)
    y0 = sim.state

    # Untimed pass: evaluations, the balance residual after every step, the samples.
    counted = _Counted(sim.dynamics.function)
    y, samples, residual = y0, [y0], 0.0
    for n in range(1, total + 1):
        y = step(counted, y, step_size)
        sim.state = y
        books = abs(sim.residual())
        residual = max(residual, books if isfinite(books) else float("inf"))
        if n % every == 0:
            samples.append(y)
    sim.state = y0

    # Timed pass: stepping and sampling only, the fastest of a few repeats.
    f, best, spent = sim.dynamics.function, float("inf"), 0.0
    while spent < MIN_TIMED_CPU_S or best == float("inf"):
        start = time.process_time()
        y, kept = y0, []
        for n in range(1, total + 1):
            y = step(f, y, step_size)
            if n % every == 0:
                kept.append(y)
        elapsed = time.process_time() - start
        best, spent = min(best, elapsed), spent + elapsed

    def worst(values):
        # A non-finite result is infinitely wrong, not silently skipped by max().
        return max((v if isfinite(v) else float("inf") for v in values), default=0.0)

    state_error = worst(abs(a - b) for s, r in zip(samples, ref) for a, b in zip(s[:4], r[:4]))
    drift = worst(abs(sim.energy(s) - sim.energy(r)) for s, r in zip(samples, ref))
    duration = times[-1] - times[0]
    return Run(name, step_size, tolerance, state_error, drift, residual, counted.calls,
               best / duration if duration > 0 else 0.0)


def fitted_order(runs: list[Run]) -> float | None:
    """Least-squares slope of log(error) against log(h) over the asymptotic points."""
    low, high = ORDER_FIT_RANGE
    points = [(log(r.step_size), log(r.max_state_error)) for r in runs
              if low < r.max_state_error < high]
    if len({x for x, _ in points}) < 2:
        return None
    mx = sum(x for x, _ in points) / len(points)
    my = sum(y for _, y in points) / len(points)
    return (sum((x - mx) * (y - my) for x, y in points)
            / sum((x - mx) ** 2 for x, _ in points))


def study(scene: Scene, duration: float, integrators, steps, tolerances, progress=None) -> dict:
    """Every requested run plus fitted orders; `progress(done, total, label)` if given."""
    fixed = [n for n in integrators if not INTEGRATORS[n].adaptive]
    adaptive = [n for n in integrators if INTEGRATORS[n].adaptive]
    plan = ([(n, h, None) for n in fixed for h in steps]
            + [(n, scene.step_size, tol) for n in adaptive for tol in tolerances])
    interval = max([h for _, h, _ in plan] + [scene.step_size])
    times = sample_times(scene, duration, interval)
    for _, h, _ in plan:
        scene.steps_for(interval, h)          # every method must land on the sample times
    ref = reference(scene, times)
    runs = []
    for i, (name, h, tol) in enumerate(plan):
        if progress:
            progress(i, len(plan), f"{name} {'h' if tol is None else 'tol'}={tol or h:g}")
        runs.append(measure(scene, name, h, tol, times, ref))
    if progress:
        progress(len(plan), len(plan), "done")
    orders = {n: fitted_order([r for r in runs if r.integrator == n]) for n in fixed}
    return {"scene": scene.name, "duration": duration, "sample_interval": interval,
            "reference": f"scipy solve_ivp DOP853 rtol=atol={REFERENCE_TOLERANCE:g}",
            "runs": [asdict(r) for r in runs],
            "orders": {n: {"fitted": o, "theory": INTEGRATORS[n].order} for n, o in orders.items()}}


def format_table(result: dict) -> str:
    header = (f"{'method':<20} {'h (s)':>9} {'tol':>7} {'max |state err|':>15} "
              f"{'energy drift J':>14} {'residual J':>10} {'rhs evals':>9} {'CPU s/sim s':>11}")
    lines = [f"scene {result['scene']}, {result['duration']:g} s, compared every "
             f"{result['sample_interval']:g} s with {result['reference']}", header,
             "-" * len(header)]
    for r in result["runs"]:
        tol = "" if r["tolerance"] is None else f"{r['tolerance']:.0e}"
        lines.append(f"{r['integrator']:<20} {r['step_size']:>9g} {tol:>7} "
                     f"{r['max_state_error']:>15.3e} {r['energy_drift']:>14.3e} "
                     f"{r['balance_residual']:>10.2e} {r['rhs_evaluations']:>9d} "
                     f"{r['cpu_s_per_sim_s']:>11.2e}")
    lines.append("")
    for name, o in result["orders"].items():
        fitted = "n/a (too few points in range)" if o["fitted"] is None else f"{o['fitted']:.2f}"
        lines.append(f"fitted order {name:<20} {fitted}  (theory {o['theory']})")
    return "\n".join(lines)


def cheapest(result: dict, target: float):
    """The run reaching max state error <= target at the least CPU time, or None."""
    good = [r for r in result["runs"] if r["max_state_error"] <= target]
    return min(good, key=lambda r: r["cpu_s_per_sim_s"], default=None)


def plot(result: dict, path: str) -> None:
    """Work-precision diagram: max state error against CPU time, log-log, one line per method."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8.5, 5.5), dpi=100)
    markers = "osD^v<>p"
    names = list(dict.fromkeys(r["integrator"] for r in result["runs"]))
    for i, name in enumerate(names):
        runs = [r for r in result["runs"] if r["integrator"] == name
                and isfinite(r["max_state_error"]) and r["max_state_error"] > 0]
        order = result["orders"].get(name, {}).get("fitted")
        label = name + (f" (order {order:.2f})" if order is not None else
                        " (tolerance 1e-4 … 1e-12)" if runs and runs[0]["tolerance"] else "")
        ax.loglog([r["cpu_s_per_sim_s"] for r in runs], [r["max_state_error"] for r in runs],
                  marker=markers[i % len(markers)], label=label)
        if name in ("rk4", "dopri5"):     # what each point is, on the lines people pick from
            labels: dict = {}             # runs with the same result share one label
            for r in runs:
                text = f"h={r['step_size']:g}" if r["tolerance"] is None else f"{r['tolerance']:g}"
                labels.setdefault(r["max_state_error"], [r["cpu_s_per_sim_s"]]).append(text)
            for error, (cpu, *texts) in labels.items():
                text = ", ".join(texts) if name == "rk4" else "tol " + ", ".join(texts)
                ax.annotate(text, (cpu, error), fontsize=7, textcoords="offset points",
                            xytext=(-6, -10) if name == "rk4" else (4, -11),
                            ha="right" if name == "rk4" else "left")
    ax.axhline(1e-6, color="grey", linestyle=":", linewidth=1)
    ax.annotate("1e-6", (1.0, 1e-6), xycoords=("axes fraction", "data"), xytext=(-4, 3),
                textcoords="offset points", ha="right", fontsize=8, color="grey")
    ax.set_xlabel("CPU seconds per simulated second (lower is cheaper)")
    ax.set_ylabel("max |state error| vs DOP853 reference")
    ax.set_title(f"What accuracy costs: scene {result['scene']}, {result['duration']:g} s")
    ax.grid(True, which="major", alpha=0.4)
    ax.legend(fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _positive_list(values, what: str, above: float = 0.0, below: float | None = None) -> list[float]:
    for v in values:
        if not (isfinite(v) and v > above and (below is None or v < below)):
            limit = f" and below {below:g}" if below is not None else ""
            raise SceneError(f"{what} {v:g} must be a finite number above {above:g}{limit}")
    return list(values)


def check_plan(scene: Scene, duration: float, steps, tolerances) -> None:
    """Refuse, before the reference is computed, a plan the study cannot carry out."""
    interval = max(list(steps) + [scene.step_size])
    for h in steps:
        if abs(round(interval / h) * h - interval) > 1e-9 * interval:
            raise UsageError(f"--steps {h:g} does not divide {interval:g}, the largest step, "
                             "where every run is compared; choose steps that divide it")
        if duration / h > MAX_RUN_STEPS:
            raise UsageError(f"--steps {h:g} over {duration:g} s is {duration / h:.3g} steps; "
                             f"the study allows {MAX_RUN_STEPS:.0e} per run: use a larger step "
                             "or a shorter --duration")
    if tolerances and duration / scene.step_size > MAX_RUN_STEPS:
        raise UsageError(f"the scene's step {scene.step_size:g} s over {duration:g} s is too "
                         f"many steps for the study ({MAX_RUN_STEPS:.0e} per run)")
    sample_times(scene, duration, interval)


def cmd_accuracy(args) -> int:
    json_path = args.json and check_output(args.json, "--json", args.force, suffixes=(".json",))
    plot_path = args.plot and check_output(args.plot, "--plot", args.force, suffixes=PLOT_FORMATS)
    scene = scene_from_args(args)
    unknown = [n for n in args.integrators if n not in INTEGRATORS]
    if unknown:
        raise UsageError(f"unknown integrator {unknown[0]!r}; choose from {', '.join(INTEGRATORS)}")
    steps = _positive_list(args.steps, "step size")
    # Below ~1e-14 double precision cannot meet the tolerance (scipy refuses it too).
    tolerances = _positive_list(args.tolerances, "tolerance", above=MIN_TOLERANCE, below=1.0)
    if args.duration is not None and not (isfinite(args.duration) and args.duration > 0):
        raise UsageError(f"--duration {args.duration:g} must be a positive number of seconds")
    check_plan(scene, args.duration, steps, tolerances)
    with Progress(1.0, "arm-sim accuracy", unit="runs") as progress:
        def report(done, total, label):
            progress.total = total
            progress.update(done)
        result = study(scene, args.duration, args.integrators, steps, tolerances, report)
    print(format_table(result))
    best = cheapest(result, 1e-6)
    if best:
        print(f"cheapest run with max state error <= 1e-6: {best['integrator']} "
              f"h={best['step_size']:g}" + (f" tol={best['tolerance']:g}" if best["tolerance"] else "")
              + f" ({best['cpu_s_per_sim_s']:.2e} CPU s per simulated s)")
    if json_path:
        clear_output(json_path)
        write_text(json_path, strict_json(result, indent=1), "--json")
    if plot_path:
        clear_output(plot_path)
        try:
            plot(result, str(plot_path))
        except OSError as error:
            Path(plot_path).unlink(missing_ok=True)
            raise UsageError(f"--plot {plot_path}: cannot write: {error.strerror}") from None
    return 0


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("accuracy", help="work-precision study: error, drift and CPU cost "
                                               "of every integrator against a DOP853 reference")
    add_scene_arguments(p)
    p.add_argument("--duration", type=float, default=2.0, help="simulated seconds (default 2)")
    p.add_argument("--integrators", nargs="+", default=list(INTEGRATORS), metavar="NAME",
                   help=f"methods to compare (default all: {' '.join(INTEGRATORS)})")
    p.add_argument("--steps", nargs="+", type=float, default=list(DEFAULT_STEPS), metavar="H",
                   help="step sizes for fixed-step methods (each must divide the largest)")
    p.add_argument("--tolerances", nargs="+", type=float, default=list(DEFAULT_TOLERANCES),
                   metavar="TOL", help="rtol = atol values for embedded pairs, stepping at the "
                                       "scene's publish step")
    p.add_argument("--json", metavar="PATH", help="write every run and the fitted orders as JSON")
    p.add_argument("--plot", metavar="PATH", help="write the work-precision diagram "
                                                  "(.png, .svg or .pdf)")
    p.add_argument("--force", action="store_true", help="replace an existing --json or --plot")
    p.set_defaults(func=cmd_accuracy)
