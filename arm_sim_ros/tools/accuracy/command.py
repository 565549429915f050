"""What accuracy costs: a work-precision study of every integrator on any scene.

Each method runs the scene at several step sizes (embedded pairs: several tolerances at
the scene's publish step) and is compared with a high-accuracy reference, scipy's DOP853
at rtol = atol = 1e-13, at the same physical times. The reference is built from
`model.forward_dynamics`, not from the generated right-hand side, so it also checks that
code. Reported per run: max state error, energy drift, balance residual, sub-steps taken,
CPU seconds per simulated second, its path and its estimate mode; per fixed-step method, the
fitted convergence order.

Every run of ours goes through `Simulator.run` on the path the user has (compiled where
numba is installed), once with the error estimate (`estimate` global, tolerance 0: the
estimate alone) and once without (off), at the same steps; beside them the scene as set,
a sweep of the scene key `tolerance` for the fixed-step methods of order >= 3, and the
node's path (the scene as set through `Simulator.step`, a Python call per step). MuJoCo's
integrators run the same scene at the same step sizes (mujoco_peer.py), priced twice: mj_step
in a Python loop and mujoco.rollout. A run's price is the CPU time of the whole run, the
fastest of its calls over --repeat rounds in which every run of the scene is called in turn,
call by call (timing.py), so that the same trajectory costs the same in every series. Scenes that switch modes (friction, joint limits)
have a reference that locates every switch (independent.py, runs.hybrid_reference).
"""
from __future__ import annotations

import argparse
from dataclasses import asdict
from math import isfinite, log

from ...outputs import check_output, clear_output, strict_json, write_text
from ...physics.stepping.integrators import INTEGRATORS
from ...physics.scene import Scene, SceneError
from ...physics.simulator import Simulator
from ...usage import UsageError
from . import report as report
from . import mujoco_peer
from .report import TARGET, cheapest  # noqa: F401  (part of the study's interface)
from . import timing
from .runs import (ESTIMATES, Run, measure, measure_mujoco, measure_node,  # noqa: F401
                   measure_simulator, reference, reference_and_label, sample_times)
from ..arguments import add_scene_arguments, scene_from_args
from ..progress import Progress

MAX_RUN_STEPS = 10_000_000      # steps per run; beyond, a study would run for hours
PLOT_FORMATS = (".png", ".svg", ".pdf")
DEFAULT_STEPS = (0.02, 0.01, 0.005, 0.0025, 0.00125, 0.000625, 0.0003125, 0.00015625)
DEFAULT_TOLERANCES = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)
# Errors used to fit an order: below, the reference and round-off dominate; above, the
# method is not yet in its asymptotic regime.
ORDER_FIT_RANGE = (1e-11, 0.3)
MIN_TOLERANCE = 1e-14
DEFAULT_SWEEP = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9)   # the scene key `tolerance`
SWEEP_MIN_ORDER = 3     # lower orders would need up to 10^4 sub-steps a step to meet these
PEERS = ("mujoco",)


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


def has_estimate(scene: Scene) -> bool:
    """True where the scene's steps carry an error estimate, so a tolerance can act."""
    estimate = Simulator(scene).error_estimate
    return estimate == estimate                 # NaN: the stability plan refuses the steps


def plan_runs(scene, times, ref, integrators, steps, tolerances, sweep, peers):
    """[(label, measure thunk: [timing.Priced])] of every run of the study, the node's path
    included, and the notes on what was left out."""
    fixed = [n for n in integrators if not INTEGRATORS[n].adaptive]
    adaptive = [n for n in integrators if INTEGRATORS[n].adaptive]
    plan = [(f"{n} h={h:g}, estimate {e}", lambda n=n, h=h, e=e: [
        measure(scene, n, h, None, times, ref, e)])
        for n in fixed for e in ESTIMATES for h in steps]
    plan += [(f"{n} tol={t:g}, estimate {e}", lambda n=n, t=t, e=e: [
        measure(scene, n, scene.step_size, t, times, ref, e)])
        for n in adaptive for e in ESTIMATES for t in tolerances]
    plan.append(("as set", lambda: [measure_simulator(scene, times, ref, "as set")]))
    plan.append(("the node's path", lambda: [measure_node(scene, times, ref)]))
    notes = []
    swept = [n for n in fixed if INTEGRATORS[n].order >= SWEEP_MIN_ORDER]
    if sweep and swept and not has_estimate(scene.replace(integrator=swept[0], tolerance=0.0,
                                                          estimate="global")):
        notes.append("tolerance sweep: none (the stability plan refuses this scene's steps, "
                     "so they carry no error estimate and a tolerance does not act)")
        swept = []
    plan += [(f"{n} tolerance={t:g}", lambda n=n, t=t: [measure_simulator(
        scene.replace(integrator=n, tolerance=t, estimate="global"), times, ref, "tolerance")])
        for n in swept for t in sweep]
    peer = {}
    if "mujoco" in peers:
        why = mujoco_peer.available()
        try:
            peer = {"notes": mujoco_peer.check(scene)} if why is None else {"unavailable": why}
        except mujoco_peer.Unsupported as error:
            peer = {"unavailable": f"not built in MuJoCo here: {error}"}
        if "notes" in peer:
            peer["version"] = mujoco_peer.version()
            plan += [(f"mujoco {i} h={h:g}", lambda i=i, h=h: measure_mujoco(
                scene, i, h, times, ref)) for i in mujoco_peer.INTEGRATORS for h in steps]
        else:
            notes.append(f"MuJoCo: {peer['unavailable']}")
    return plan, notes, peer


def study(scene: Scene, duration: float, integrators, steps, tolerances, progress=None,
          sweep=(), peers=(), repeat: int = 1) -> dict:
    """Every requested run plus fitted orders; `progress(done, total, label)` if given.
    Every run is measured first, then priced in `repeat` rounds over all of them in turn."""
    fixed = [n for n in integrators if not INTEGRATORS[n].adaptive]
    interval = max(list(steps) + [scene.step_size])
    times = sample_times(scene, duration, interval)
    for h in steps:
        scene.steps_for(interval, h)          # every method must land on the sample times
    ref, label = reference_and_label(scene, times)
    plan, notes, peer = plan_runs(scene, times, ref, integrators, steps, tolerances, sweep,
                                  peers)
    units = len(plan) * (1 + repeat)
    priced = []
    for i, (text, measured) in enumerate(plan):
        if progress:
            progress(i, units, f"{scene.name}: {text}")
        priced += measured()
    timing.price(priced, repeat, times[-1] - times[0], progress and (
        lambda done, total: progress(len(plan) + done * len(plan) * repeat // total, units,
                                     f"{scene.name}: pricing")))
    runs = [p.run for p in priced if p.run.kind != "node"]
    node = next(p.run for p in priced if p.run.kind == "node")
    orders = {n: fitted_order([r for r in runs if r.series == n]) for n in fixed}
    if "notes" in peer and any(getattr(scene, e) is not None for e in mujoco_peer.SOFT):
        theirs = [r.max_state_error for r in runs if r.kind.startswith("mujoco")]
        peer["floor"] = min(theirs)   # soft constraints: MuJoCo's error stops falling here
    as_set = next(r for r in runs if r.kind == "as set")
    return {"scene": scene.name, "duration": duration, "sample_interval": interval,
            "reference": label, "path": as_set.path, "runs": [asdict(r) for r in runs],
            "node": asdict(node), "notes": notes, "peers": {"mujoco": peer} if peer else {},
            "orders": {n: {"fitted": o, "theory": INTEGRATORS[n].order} for n, o in orders.items()}}


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
    if duration / scene.step_size > MAX_RUN_STEPS:
        raise UsageError(f"the scene's step {scene.step_size:g} s over {duration:g} s is too "
                         f"many steps for the study ({MAX_RUN_STEPS:.0e} per run)")
    sample_times(scene, duration, interval)


def scenes_from_args(args) -> list[Scene]:
    """--scenes (each with --step and --set applied), else --scene."""
    names = args.scenes or [args.scene]
    return [scene_from_args(argparse.Namespace(**{**vars(args), "scene": n})) for n in names]


def cmd_accuracy(args) -> int:
    json_path = args.json and check_output(args.json, "--json", args.force, suffixes=(".json",))
    plot_path = args.plot and check_output(args.plot, "--plot", args.force, suffixes=PLOT_FORMATS)
    if plot_path:
        report.check_plotting()
    scenes = scenes_from_args(args)
    unknown = [n for n in args.integrators if n not in INTEGRATORS]
    if unknown:
        raise UsageError(f"unknown integrator {unknown[0]!r}; choose from {', '.join(INTEGRATORS)}")
    peers = [] if args.peers == ["none"] else args.peers
    unknown = [p for p in peers if p not in PEERS]
    if unknown:
        raise UsageError(f"unknown peer {unknown[0]!r}; choose from {', '.join(PEERS)} or none")
    steps = _positive_list(args.steps, "step size")
    # Below ~1e-14 double precision cannot meet the tolerance (scipy refuses it too).
    tolerances = _positive_list(args.tolerances, "tolerance", above=MIN_TOLERANCE, below=1.0)
    sweep = _positive_list(args.tolerance_sweep, "--tolerance-sweep value")
    if args.duration is not None and not (isfinite(args.duration) and args.duration > 0):
        raise UsageError(f"--duration {args.duration:g} must be a positive number of seconds")
    if args.repeat < 1:
        raise UsageError(f"--repeat {args.repeat} must be at least 1")
    for scene in scenes:
        check_plan(scene, args.duration, steps, tolerances)
    if "mujoco" in peers and mujoco_peer.available():
        print(f"peers: {mujoco_peer.available()}; the study goes on without it", flush=True)
    results = []
    # a pass: a run measured, or priced in one of the --repeat rounds
    with Progress(1.0, "arm-sim accuracy", unit="passes") as progress:
        for k, scene in enumerate(scenes):
            def tell(done, total, label, k=k):
                progress.total = total * len(scenes)
                progress.update(k * total + done)
            results.append(study(scene, args.duration, args.integrators, steps, tolerances,
                                 tell, sweep, peers, args.repeat))
    print("\n\n".join(report.format_table(r) for r in results))
    print()
    print(report.price_list(results, TARGET))
    if json_path:
        clear_output(json_path)
        document = results[0] if len(results) == 1 else {"scenes": results}
        write_text(json_path, strict_json(document, indent=1), "--json")
    if plot_path:
        clear_output(plot_path)
        report.write_plot(results, plot_path)
    return 0


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("accuracy", help="work-precision study: error, drift and CPU cost "
                                               "of every integrator, a tolerance sweep and "
                                               "MuJoCo against a DOP853 reference")
    add_scene_arguments(p)
    p.add_argument("--scenes", nargs="+", metavar="NAME",
                   help="several scenes, one panel each (instead of --scene)")
    p.add_argument("--duration", type=float, default=2.0, help="simulated seconds (default 2)")
    p.add_argument("--integrators", nargs="+", default=list(INTEGRATORS), metavar="NAME",
                   help=f"methods to compare (default all: {' '.join(INTEGRATORS)})")
    p.add_argument("--steps", nargs="+", type=float, default=list(DEFAULT_STEPS), metavar="H",
                   help="step sizes for fixed-step methods and MuJoCo (each must divide the "
                        "largest)")
    p.add_argument("--tolerances", nargs="+", type=float, default=list(DEFAULT_TOLERANCES),
                   metavar="TOL", help="rtol = atol values for embedded pairs, stepping at the "
                                       "scene's publish step")
    p.add_argument("--tolerance-sweep", nargs="*", type=float, default=list(DEFAULT_SWEEP),
                   metavar="TOL", help="values of the scene key `tolerance` for the fixed-step "
                                       "methods of order >= 3 at the scene's step (none: off)")
    p.add_argument("--peers", nargs="+", default=list(PEERS), metavar="NAME",
                   help="simulators run side by side: mujoco (default when installed) or none")
    p.add_argument("--repeat", type=int, default=3,
                   help="rounds of timing over every run, the fastest counts (default 3)")
    p.add_argument("--json", metavar="PATH", help="write every run and the fitted orders as JSON")
    p.add_argument("--plot", metavar="PATH", help="write the work-precision diagram "
                                                  "(.png, .svg or .pdf)")
    p.add_argument("--force", action="store_true", help="replace an existing --json or --plot")
    p.set_defaults(func=cmd_accuracy)
