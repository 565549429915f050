"""`arm-sim fit BAG --scene BASE --free KEY[,KEY...]`: fit scene keys to a recording.

System identification: the recording's torques are replayed through our Simulator and the
free keys fitted by least squares on the simulated positions and velocities (multiple
shooting, fit_problem.py), from several starts run in parallel on local processes
(--workers) or a Dask cluster (--scheduler); uncertainties, what the data do not excite
and the held-out validation error follow (fit_stats.py); the fitted scene is written as a
YAML that `arm-sim run --scene` takes, the report as a PNG or a Rerun recording
(fit_report.py). Several BAGs make one fit, one set of parameters for every recording:
each is first fitted alone (all starts of all recordings in parallel), then all together
from the median of those fits; the text and --json give each recording's own values too.

Every fit ends within bounds it states (bounds.py: steps per sample, the problem's size,
evaluations per start, wall time) and says why it stopped; its verdict says whether the
fitted model explains the recording (within 2 x the noise on every channel).

Exit codes: 0 the fitted model explains the recording, 1 a bound was reached before the
fit converged (one line: why, and the best point found) or the recording cannot identify a
free key (one line: which, and why; stats.py), 2 bad input (one line), 3 the fit converged
but the model does not explain the recording (the outputs are written, the verdict says by
how much: the base scene lacks something the arm has).
"""
from __future__ import annotations

import os
import sys
import time
from dataclasses import fields

import numpy as np

from ...interface import JOINT_NAMES
from ...outputs import check_output, clear_output, strict_json, write_text
from ...physics.scene import Scene
from ..arguments import add_scene_arguments, scene_from_args
from . import bounds as b
from .data import FitError, read_recording
from .keys import check_free, parse_free, with_values
from .problem import SEGMENT_SECONDS, VALIDATION_FRACTION, Problem, fit_from, starts
from .stats import Unidentified, check_motion, unidentified, uncertainty, validate, warnings_for

CONNECT_SECONDS = 10.0      # a --scheduler that has not answered by then is given up
# setup.py's extra `fit` (a test checks that they agree): what --scheduler needs
FIT_EXTRA = ("dask==2026.8.0", "distributed==2026.8.0")
CONNECT_GRACE = 5.0         # then Client's own timeout may still say why (refused, not Dask)


class Stopped(Exception):
    """A bound reached with nothing to report but why (exit code 1)."""

DEFAULT_STARTS = 2          # the base scene's values and one spread start; more: --starts
DEFAULT_EVALUATIONS = 60     # least-squares iterations of one start before it gives up


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "fit", help="fit scene keys (damping, friction, rotor inertia, payload...) to a recording",
        description=__doc__.splitlines()[0])
    p.add_argument("bags", nargs="+", metavar="BAG",
                   help="rosbag2 directory (MCAP or sqlite3) or .csv; several: one joint fit")
    add_scene_arguments(p)
    p.add_argument("--free", required=True, metavar="KEY[,KEY...]",
                   help="scene keys to fit, e.g. damping,friction.coulomb[1],payload.mass")
    p.add_argument("-o", "--output", metavar="FITTED.yaml", help="write the fitted scene")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--report", metavar="PATH", help="write a report: .png or Rerun .rrd")
    p.add_argument("--torque-topic", metavar="TOPIC",
                   help="take the torque from joint_torque_commands or joint_commands "
                        "(default: the JointState effort)")
    p.add_argument("--joint-names", default=",".join(JOINT_NAMES),
                   help=f"the recording's joint names (default {','.join(JOINT_NAMES)})")
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="local processes for the starts (default and most: the CPU count)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the starts on a Dask cluster, e.g. tcp://127.0.0.1:8786")
    p.add_argument("--starts", type=int, default=DEFAULT_STARTS,
                   help=f"multi-start count (default {DEFAULT_STARTS})")
    p.add_argument("--segment", type=float, default=SEGMENT_SECONDS,
                   help=f"multiple-shooting segment length, s (default {SEGMENT_SECONDS:g})")
    p.add_argument("--validation", type=float, default=VALIDATION_FRACTION,
                   help=f"fraction held out at the end (default {VALIDATION_FRACTION:g})")
    p.add_argument("--max-evaluations", type=int, default=DEFAULT_EVALUATIONS,
                   help=f"per start (default {DEFAULT_EVALUATIONS})")
    p.add_argument("--max-seconds", type=float, default=b.DEFAULT_SECONDS,
                   help=f"wall time of the whole fit, s (default {b.DEFAULT_SECONDS:g}): "
                        "each start stops there with its best point")
    p.add_argument("--force", action="store_true", help="replace an existing -o or --report")
    p.set_defaults(func=cmd_fit)


def checked_args(args) -> tuple:
    """The joint names, and every option a person could give wrong refused in one line."""
    for name, low in (("workers", 1), ("starts", 1), ("max_evaluations", 1)):
        if getattr(args, name) < low:
            raise FitError(f"--{name.replace('_', '-')} must be at least {low}")
    if not (args.segment > 0 and 0 <= args.validation < 0.9):
        raise FitError("--segment must be positive seconds and --validation a fraction below 0.9")
    if not 0 < args.max_seconds < float("inf"):
        raise FitError(f"--max-seconds {args.max_seconds:g} must be a positive number of seconds")
    names = tuple(n.strip() for n in args.joint_names.split(","))
    if len(names) != 2 or not all(names):
        raise FitError(f"--joint-names {args.joint_names!r}: two names, shoulder first")
    if names[0] == names[1]:
        raise FitError(f"--joint-names {args.joint_names!r} names {names[0]} twice: the "
                       "shoulder and the elbow are two joints")
    paths = [os.path.realpath(path) for path in args.bags]
    for k, path in enumerate(paths):
        if path in paths[:k]:
            raise FitError(f"{args.bags[k]} is given twice: a recording counts once")
    if args.scheduler:
        dask_client()                      # before anything is read or fitted
    cpus = os.cpu_count() or 1
    if args.workers > cpus and not args.scheduler:
        print(f"arm-sim: --workers {args.workers}: {cpus} processes, one per CPU",
              file=sys.stderr)
        args.workers = cpus
    return names


def cmd_fit(args) -> int:
    started, deadline = time.perf_counter(), time.time() + args.max_seconds
    names = checked_args(args)
    wanted = ((args.output, "-o", (".yaml", ".yml")), (args.report, "--report", (".png", ".rrd")))
    outputs = [check_output(path, option, args.force, suffixes=suffixes)
               for path, option, suffixes in wanted if path is not None]
    base = scene_from_args(args)
    free = parse_free(args.free, base)
    check_free(base, free)
    recordings = [read_recording(path, names, args.torque_topic) for path in args.bags]
    mode = "commands" if args.torque_topic else "effort"
    problem = Problem(base, free, recordings, mode, args.segment, args.validation)
    b.check_size(problem)
    try:
        check_motion(problem)
    except Unidentified as nothing:
        print(f"arm-sim: error: {nothing}", file=sys.stderr)
        return b.UNIDENTIFIED_CODE
    points = starts(len(free), args.starts)
    # Every start on every recording alone, in parallel; several recordings are then
    # fitted together from the median of their own fits (one more start, near the optimum).
    alone = [problem] if len(recordings) == 1 else [
        Problem(base, free, [r], mode, args.segment, args.validation) for r in recordings]
    try:
        results = run_tasks(fit_from, [(p, x0, args.max_evaluations, deadline) for p in alone
                                       for x0 in points], args.workers, args.scheduler, deadline)
    except Stopped as stop:
        print(f"arm-sim: error: {stop}", file=sys.stderr)
        return b.STOPPED_CODE
    per_recording = [min(results[k * len(points):(k + 1) * len(points)], key=lambda r: r["cost"])
                     for k in range(len(alone))]
    if len(recordings) > 1:
        joint = np.median([r["xp"] for r in per_recording], axis=0)
        results = [fit_from(problem, joint, args.max_evaluations, deadline)]
    best = min(results, key=lambda r: r["cost"])
    if best["status"] <= 0:           # stopped at a bound: why, and where it got to
        point = ", ".join(f"{p.key} = {v:.6g}" for p, v in zip(free, problem.values(best["xp"])))
        print(f"arm-sim: error: the fit stopped at "
              f"{b.stopped(best, args.max_evaluations, args.max_seconds)} before it converged, "
              f"from each of {len(points)} starts; best point: {point}", file=sys.stderr)
        return b.STOPPED_CODE
    try:
        outcome = summarise(problem, results, names, deadline)
    except Unidentified as unknown:
        print(f"arm-sim: error: {unknown}", file=sys.stderr)
        return b.UNIDENTIFIED_CODE
    outcome["start_count"] = len(points)
    outcome["recordings"] = [{"source": r.source, "values": problem.values(best["xp"]).tolist(),
                              "converged": best["status"] > 0}
                             for r, best in zip(recordings, per_recording)]
    outcome["seconds"] = time.perf_counter() - started
    outcome["bounds"] = b.bounds(args)
    outcome["stopped"] = b.stopped(results[outcome["best_start"]], args.max_evaluations,
                                   args.max_seconds)
    outcome["verdict"] = b.verdict(outcome)
    outcome["explains"] = outcome["verdict"]["explains"]
    for path in outputs:
        clear_output(path)
    fitted = fitted_scene(problem, outcome)
    outcome["scene"] = args.output
    if args.output:
        write_text(args.output, scene_yaml(fitted, outcome, args.bags), "-o")
    if args.report:
        from .report import write_report
        write_report(args.report, problem, outcome, names)
    print(strict_json(public(outcome)) if args.json else describe(problem, outcome, names))
    return b.EXPLAINED_CODE if outcome["explains"] else b.UNEXPLAINED_CODE


def run_tasks(function, tasks, workers: int, scheduler: str | None, deadline: float) -> list:
    """function(*task) for every task, in order: on a Dask cluster at `scheduler`, else on
    `workers` local processes (1: here). Each task is deterministic, so the results are the
    same wherever they run; each stops at `deadline` (time.time()) by itself, and a cluster
    that has returned nothing by then is given up (Stopped)."""
    if scheduler:
        with connected(scheduler) as client:
            from distributed import wait
            futures = [client.submit(function, *task, pure=False) for task in tasks]
            try:
                wait(futures, timeout=max(1.0, deadline - time.time() + CONNECT_SECONDS))
            except TimeoutError:
                raise Stopped(f"--scheduler {scheduler}: no result within the wall-time bound "
                              "(--max-seconds): does it have workers?") from None
            return client.gather(futures)
    if workers <= 1 or len(tasks) <= 1:
        return [function(*task) for task in tasks]
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    with ProcessPoolExecutor(min(workers, len(tasks)), mp_context=get_context("spawn")) as pool:
        return list(pool.map(function, *zip(*tasks)))


def dask_client():
    """distributed.Client, or FitError naming the extra that installs it."""
    try:
        from distributed import Client
    except ImportError as error:
        raise FitError(f"--scheduler needs dask.distributed, which does not import here "
                       f"({error}): pip install 'arm_sim_ros[fit]' (the extra fit: "
                       f"{' '.join(FIT_EXTRA)})") from None
    return Client


def connected(scheduler: str):
    """A Dask client of `scheduler`, or FitError in one line: no Dask, nobody there, not a
    Dask scheduler (an HTTP port answers nonsense), or silent past CONNECT_SECONDS (Client's
    own timeout does not cover a server that accepts and says nothing)."""
    Client = dask_client()
    import threading

    made = []

    def connect():
        try:
            made.append(Client(scheduler, timeout=f"{CONNECT_SECONDS:g}s"))
        except BaseException as error:   # noqa: BLE001 - whatever it is, it is said below
            made.append(error)

    thread = threading.Thread(target=connect, daemon=True)
    thread.start()
    thread.join(CONNECT_SECONDS + CONNECT_GRACE)
    if not made:
        raise FitError(f"--scheduler {scheduler}: no answer in {CONNECT_SECONDS:g} s (is it a "
                       "Dask scheduler, e.g. tcp://host:8786?)")
    if isinstance(made[0], BaseException):
        error = made[0]
        kind = "cannot reach it" if isinstance(error, (OSError, TimeoutError)) else (
            "not a Dask scheduler (is it its dashboard's HTTP port?)")
        raise FitError(f"--scheduler {scheduler}: {kind} ({type(error).__name__}: "
                       f"{str(error)[:120]})")
    return made[0]


def summarise(problem: Problem, results, names, deadline=None) -> dict:
    """The best start, its uncertainties, warnings and validation, as plain data; or
    Unidentified, naming the free keys the fitted simulation shows nothing of."""
    best = min(range(len(results)), key=lambda i: results[i]["cost"])
    r = results[best]
    xp, states = r["xp"], r["states"]
    blocks = problem.residuals(xp, states, problem.training)
    residuals = np.concatenate(blocks)
    jac = problem.jacobian(xp, states, problem.training, blocks)
    stats = uncertainty(jac, residuals, problem.n_parameters)
    fitted = with_values(problem.base, problem.free, problem.values(xp))
    values = np.array([p.value(fitted) for p in problem.free])   # Fs below Fc acts as Fc
    values[problem.sensing] = problem.values(xp)[problem.sensing]   # delays: not rounded
    se = stats["se"] * problem.scale
    runs = problem.simulate(xp, states, problem.training)
    unknown = unidentified(problem, stats["moved"], runs, names)
    if unknown:
        rest = [f"{p.key} = {v:.6g}" for i, (p, v) in enumerate(zip(problem.free, values))
                if i not in unknown]
        raise Unidentified("the recording cannot identify " + "; ".join(unknown.values())
                           + (f"; fitted beside: {', '.join(rest)}" if rest else "")
                           + "; free only keys it identifies")
    chi2 = 2 * r["cost"] / r["residuals"]
    warnings = warnings_for(problem, values, se, stats["correlation"], stats["moved"], chi2)
    errors = np.vstack([run - problem.measured(g) for run, g in zip(runs, problem.training)])
    start = problem.values(np.ones(problem.n_parameters))
    return {
        "converged": r["status"] > 0,
        "parameters": [{"key": p.key, "value": float(v), "se": float(s), "unit": p.unit,
                        "start": float(s0)}
                       for p, v, s, s0 in zip(problem.free, values, se, start)],
        "correlation": stats["correlation"].tolist(),
        "warnings": warnings,
        "training": {"rms": np.sqrt(np.mean(errors ** 2, axis=0)).tolist(),
                     "chi2_per_residual": chi2,
                     "segments": len(problem.training)},
        "noise": [s.tolist() for s in problem.sigma],
        "validation": validate(problem, xp, deadline),
        "starts": [{"cost": x["cost"], "status": x["status"], "evaluations": x["nfev"],
                    "message": x["message"]} for x in results],
        "best_start": best, "cost_history": r["history"], "states": states, "runs": runs,
    }


def public(outcome: dict) -> dict:
    """The outcome without the arrays the report draws."""
    out = {k: v for k, v in outcome.items() if k not in ("states", "runs")}
    if out["validation"] is not None:
        out["validation"] = {k: v for k, v in out["validation"].items()
                             if k not in ("states", "runs")}
    return out


def fitted_scene(problem: Problem, outcome: dict) -> Scene:
    """The base scene with the fitted values, starting where the first recording did (its
    fitted start state) and lasting as long (whole steps)."""
    scene = with_values(problem.base, problem.free, [p["value"] for p in outcome["parameters"]])
    first = problem.training[0]
    start = problem.measured(first)[0] + problem.sigma[first.recording] * outcome["states"][:4]
    steps = int(problem.recordings[0].duration / scene.step_size + 1e-9)
    return scene.replace(initial_positions=tuple(start[:2]), initial_velocities=tuple(start[2:]),
                         duration=max(1, steps) * scene.step_size)


def scene_yaml(scene: Scene, outcome: dict, sources) -> str:
    """The scene as a YAML file `arm-sim run --scene` reads, the fit noted on top."""
    import yaml

    def plain(value):
        if isinstance(value, tuple):
            return [plain(v) for v in value]
        if isinstance(value, dict):
            return {k: plain(v) for k, v in value.items()}
        return value

    data = {f.name: plain(getattr(scene, f.name)) for f in fields(Scene)
            if f.name != "name" and getattr(scene, f.name) is not None}
    data["description"] = f"{scene.description or scene.name}; fitted to {', '.join(sources)}"
    notes = [f"#   {p['key']} = {p['value']:.6g} ± {p['se']:.2g} {p['unit']}"
             for p in outcome["parameters"]]
    return ("# Fitted by `arm-sim fit` (standard errors from the Jacobian at the optimum):\n"
            + "\n".join(notes) + "\n" + yaml.safe_dump(data, sort_keys=False))


def describe(problem: Problem, outcome: dict, names) -> str:
    """The outcome for a person."""
    recs, first = problem.recordings, problem.training[0]
    lines = [f"fit of {len(problem.free)} parameter(s) to {len(recs)} recording(s), "
             f"{sum(len(r) for r in recs)} samples at {1 / recs[0].dt:.4g} Hz; "
             f"{len(problem.training)} segments of "
             f"{recs[first.recording].dt * (first.stop - first.start - 1):.3g} s; "
             f"best of {outcome['start_count']} starts"
             + (" on each alone, then all together" if len(recs) > 1 else "")
             + f", {outcome['seconds']:.1f} s"]
    width = max(len(p["key"]) for p in outcome["parameters"])
    for p in outcome["parameters"]:
        lines.append(f"  {p['key']:{width}s} = {p['value']:.6g} ± {p['se']:.2g} {p['unit']}"
                     f"   (start {p['start']:.4g})")
    if len(problem.free) > 1:
        corr = np.array(outcome["correlation"])
        pairs = [(abs(np.nan_to_num(corr[i, j])), i, j)
                 for i in range(len(corr)) for j in range(i + 1, len(corr))]
        _, i, j = max(pairs)
        lines.append(f"largest correlation: {problem.free[i].key} ~ {problem.free[j].key} "
                     f"{corr[i, j]:+.3f}")
    noise = np.mean(outcome["noise"], axis=0)
    t = outcome["training"]["rms"]
    lines.append(f"training RMS error: q {t[0]:.3g}, {t[1]:.3g} rad; qd {t[2]:.3g}, "
                 f"{t[3]:.3g} rad/s (noise {noise[0]:.2g}, {noise[1]:.2g} rad; "
                 f"{noise[2]:.2g}, {noise[3]:.2g} rad/s)")
    v = outcome["validation"]
    if v is not None:
        lines.append(f"validation ({v['seconds']:.3g} s held out): q {v['rms'][0]:.3g}, "
                     f"{v['rms'][1]:.3g} rad; qd {v['rms'][2]:.3g}, {v['rms'][3]:.3g} rad/s = "
                     + ", ".join(f"{m:.2f}" for m in v["noise_multiple"]) + " x the noise")
    if len(outcome["recordings"]) > 1:
        lines += [f"alone, {r['source']}: " + ", ".join(
            f"{p.key} = {v:.6g}" for p, v in zip(problem.free, r["values"]))
            for r in outcome["recordings"]]
    lines += [f"warning: {w}" for w in outcome["warnings"]]
    verdict, bound = outcome["verdict"], outcome["bounds"]
    lines.append(("verdict: the model explains the recording" if verdict["explains"] else
                  "verdict: the model does NOT explain the recording")
                 + f" (at worst {verdict['worst_noise_multiple']:.3g} x the noise, "
                   f"{verdict['where']}; the rule: {verdict['rule']})")
    lines.append(f"stopped: {outcome['stopped']}; bounds: {bound['evaluations_per_start']} "
                 f"evaluations per start, {bound['seconds']:g} s, "
                 f"{bound['steps_per_sample']} steps per sample")
    if outcome.get("scene"):
        lines.append(f"wrote {outcome['scene']}")
    return "\n".join(lines)
