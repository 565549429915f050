"""`arm-sim`: run scenes offline and the tools around the node.

Every refusal is one line on stderr and exit code 2; no tracebacks for bad input.
Subcommands live beside the code they drive; each module adds its parser in
`add_parser(subparsers)` and keeps heavy imports (rerun, cyclonedds, scipy) inside
the functions that need them, so `arm-sim scenes` starts fast.
"""
from __future__ import annotations

import importlib
import os
import sys
import time

from ..physics.model import ParameterError
from ..physics.scene import Scene, SceneError, load_scene, parse_value, preset_names
from ..physics.trust.unestimated import ESTIMATES
from ..recording.csv_file import CsvRecorder
from ..recording.readouts import error_books, held_by
from ..outputs import check_output, claim_output, clear_output, strict_json
from ..usage import (BROKEN_PIPE, DONE, FAULT, REFUSED, STOPPED, ArgumentParser, UsageError,
                     exit_as_main, one_line)
from .arguments import add_scene_arguments, scene_from_args
from .run.rows import ChunkSteps
from .progress import Progress, watch_compiles
from .signals import StopOnSignals

# Modules that contribute subcommands of their own (each defines add_parser).
SUBCOMMAND_MODULES = ["arm_sim_ros.tools.accuracy.command",     # accuracy
                      "arm_sim_ros.tools.batch",        # batch
                      "arm_sim_ros.tools.inspect",      # inspect
                      "arm_sim_ros.tools.wire.record",       # record
                      "arm_sim_ros.tools.urdf",         # urdf
                      "arm_sim_ros.tools.fit.command",          # fit
                      "arm_sim_ros.tools.fit.excitation",  # excite
                      "arm_sim_ros.tools.sweep.command",   # sweep
                      "arm_sim_ros.tools.wire.send_torque"]  # send-torque

def cmd_scenes(args) -> int:
    for name in preset_names():
        print(f"{name:30s} {load_scene(name).description}")
    return 0


# Hooks other modules extend: each takes (args) and returns a recorder or None.
RUN_RECORDERS = [lambda args: CsvRecorder(args.csv) if args.csv else None,
                 lambda args: importlib.import_module("arm_sim_ros.tools.run.bag").run_recorder(args)
                 if args.bag else None,
                 lambda args: importlib.import_module("arm_sim_ros.recording.rrd.telemetry").make_recorder(
                     path=args.rerun, spawn=args.rerun_spawn, connect=args.rerun_connect)
                 if args.rerun or args.rerun_spawn or args.rerun_connect else None]   # rerun: 0.7 s


RUN_BATCH_STEPS = 1000   # steps whose states a recorder with step_batch gets in one call
CHECK_PERIOD = 0.05      # wall seconds between looks at a stop request and the progress


def run_recorded(sim, duration: float, recorders, stop=None, progress=None) -> float:
    """sim.run(duration) with every recorder seeing every step: step_batch(sim, states,
    books) once per chunk of at most RUN_BATCH_STEPS steps where a recorder has it (a
    Python call per step costs more than logging's 10 % budget; `books`: the error books
    of every books_every-th step (the least of the recorders'), as
    telemetry.RerunRecorder.step_batch takes them), else step(sim) after each step.
    Between chunks (about every CHECK_PERIOD s) it reports progress; `stop` (its .requested
    set by a signal) ends the run at the last whole step, even within a step
    (whole_steps.py): every recorder has then seen the same last step. A diverged state
    never reaches them: every state is checked as it is made (tools/run/rows.py). Returns
    the largest |residual| seen."""
    from .run.whole_steps import WholeSteps   # the simulator's module: imported with the work

    batched = [r for r in recorders if hasattr(r, "step_batch")]
    each = [r.step for r in recorders if not hasattr(r, "step_batch")]
    steps = ChunkSteps(each, bool(batched), min((r.books_every for r in batched), default=0))

    largest, left, chunk = 0.0, sim.scene.steps_for(duration, sim.step_size), 1
    end = sim.time + duration
    # a stop ends even a step under way (whole_steps.py); the compiled runs (extra `fast`,
    # no recorder) are stopped between them
    whole = WholeSteps(sim, stop) if stop is not None and (recorders or sim.kernel is None) else None
    while left > 0 and not (stop is not None and stop.requested):
        count = min(left, chunk)
        started = time.perf_counter()
        on_step = steps.on_step if recorders else None
        largest = max(largest, whole.run(count, on_step) if whole is not None
                      else sim.run(count * sim.step_size, on_step))
        steps.hand_over(sim, batched)
        left -= count
        if time.perf_counter() - started < CHECK_PERIOD / 2:   # grow chunks up to the period
            chunk = min(2 * chunk, RUN_BATCH_STEPS if recorders else 64 * RUN_BATCH_STEPS)
        if progress is not None:
            progress.update(duration - (end - sim.time))
    return largest


def check_run_outputs(args) -> list:
    """Every output of `run` checked by one rule before any work (outputs.check_output), and
    the files claimed (outputs.claim_output); returns the paths claimed."""
    if args.publish_rate is not None and not args.bag:
        raise UsageError("--publish-rate sets the JointState rate of a --bag recording; "
                         "add --bag DIR, or leave it out")
    wanted = [(args.csv, "--csv", False, ()), (args.rerun, "--rerun", False, (".rrd",)),
              (args.bag, "--bag", True, ())]
    paths = [(check_output(path, option, args.force, directory, suffixes), option, directory)
             for path, option, directory, suffixes in wanted if path is not None]
    claimed = []
    for path, option, directory in paths:
        if args.force:        # only then: what it removes is what --force replaces
            clear_output(path)
        if not directory:     # the bag's directory is claimed by its mkdir
            claimed += [path] if claim_output(path, option) else []
    if args.publish_rate is None:
        args.publish_rate = 100.0    # the default, applied here so that giving it is detectable
    return claimed


def cmd_run(args) -> int:
    from ..physics.simulator import Simulator

    scene = scene_from_args(args)
    duration = scene.duration if args.duration is None else parse_value("duration", args.duration)
    scene = scene.replace(duration=duration)
    scene.steps_for(duration)  # refuse before any file is opened
    sim = Simulator(scene)
    claimed = check_run_outputs(args)
    try:
        recorders = [r for r in (make(args) for make in RUN_RECORDERS) if r is not None]
    except BaseException:      # refused before the run: the files claimed go again
        for path in claimed:
            path.unlink(missing_ok=True)
        raise
    with StopOnSignals() as stop, Progress(duration, f"arm-sim run {scene.name}") as progress:
        for recorder in recorders:
            recorder.start(sim)
        try:
            drift = run_recorded(sim, duration, recorders, stop, progress)
        finally:
            for recorder in recorders:          # the bag's last diagnostics name the signal
                if stop.requested and hasattr(recorder, "stop_reason"):
                    recorder.stop_reason = stop.requested
            finish_all(recorders, sim)
    result = sim.sample().as_dict() | {"max_abs_energy_drift": drift, "fault": sim.fault,
                                       "refused_steps": sim.refused_steps,
                                       # NaN where the steps are not estimated: JSON's null
                                       "error_estimate": sim.error_estimate,
                                       "accumulated_error": sim.accumulated_error,
                                       # global, or off: the run carries no error estimate
                                       "estimate": scene.estimate,
                                       "interrupted_at": sim.time if stop.requested else None,
                                       "path": sim.path}   # compiled (numba) or python
    for event in sim.events:  # sub-stepping chosen, steps refused: say what was done
        print(f"arm-sim: {event.kind} at t = {event.t:g} s: {event.message}", file=sys.stderr)
    if stop.requested:
        print(f"arm-sim: interrupted ({stop.requested}) at t = {sim.time:.6f} s; every output "
              "ends at that step", file=sys.stderr)
    print(strict_json(result) if args.json else format_result(scene, result))
    return STOPPED if stop.requested else FAULT if sim.fault else DONE


def finish_all(recorders, sim) -> None:
    """Close every output even when one fails; then raise the first failure."""
    failure = None
    for recorder in recorders:
        try:
            recorder.finish(sim)
        except Exception as error:  # the others still close
            failure = failure or error
    if failure is not None:
        raise failure


def format_result(scene: Scene, r: dict) -> str:
    def pair(v):
        return "(" + ", ".join(f"{x:.6f}" for x in v) + ")"

    def estimate(v):      # NaN: the scene's steps are not estimated
        return "n/a" if v != v else f"{v:.3e}"

    books = (f"error estimate: none ({held_by(scene)})" if r["estimate"] == "off" else
             f"error estimate: latest step {estimate(r['error_estimate'])}, accumulated "
             f"{estimate(r['accumulated_error'])} (rad, rad/s: max over q, qd); {held_by(scene)}")

    currents = [f"{name} = {r[name]:.6f} A" for name in ("i1", "i2") if name in r]
    others = [f"{name} {value:.9f} J" for name, value in r["channels"].items()
              if name not in ("work", "dissipated")]
    return "\n".join([
        f"scene {scene.name}: policy {scene.policy}, h = {scene.step_size:g} s, {scene.method}",
        f"t = {r['t']:.6f} s",
        f"q = {pair(r['q'])} rad",
        f"qd = {pair(r['qd'])} rad/s",
        *([", ".join(currents)] if currents else []),
        f"tau = {pair(r['tau'])} N m",
        f"kinetic {r['kinetic']:.9f} J, potential {r['potential']:.9f} J, total {r['total']:.9f} J",
        f"actuator work {r['work']:.9f} J, dissipated {r['dissipated']:.9f} J",
        *([", ".join(others)] if others else []),
        f"balance residual {r['residual']:.3e} J, max |residual| over the run "
        f"{r['max_abs_energy_drift']:.9f} J",
        books,
    ])


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(prog="arm-sim", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, parser_class=ArgumentParser)
    sub.add_parser("scenes", help="list the preset scenes").set_defaults(func=cmd_scenes)
    run = sub.add_parser("run", help="run a scene offline and print the final state and energy")
    add_scene_arguments(run)
    run.add_argument("--duration", help="seconds of simulated time (default: the scene's)")
    run.add_argument("--estimate", choices=ESTIMATES,
                     help="global: the error estimate (the default); off: none, and so no "
                          "tolerance (sets it to 0): the steps alone, cheaper")
    run.add_argument("--json", action="store_true", help="print one JSON object")
    run.add_argument("--csv", metavar="PATH", help="write one row per step")
    run.add_argument("--rerun", metavar="PATH", help="write a Rerun recording (.rrd)")
    run.add_argument("--rerun-spawn", action="store_true", help="stream to a new Rerun viewer")
    run.add_argument("--rerun-connect", metavar="ADDR", help="stream to a viewer at host:port")
    run.add_argument("--bag", metavar="DIR", help="write a rosbag2 (MCAP) recording of the topics")
    run.add_argument("--publish-rate", type=float, metavar="HZ",
                     help="JointState rate in the --bag recording (default 100 Hz)")
    run.add_argument("--force", action="store_true",
                     help="replace an existing --csv, --rerun or --bag output")
    run.set_defaults(func=cmd_run)
    for name in SUBCOMMAND_MODULES:
        importlib.import_module(name).add_parser(sub)
    return parser


def main(argv=None) -> int:
    watch_compiles("arm-sim")   # a first compile says so, on a terminal, a file or a pipe
    try:
        args = build_parser().parse_args(argv)
        return args.func(args)
    except (UsageError, SceneError, ParameterError) as error:
        print(f"arm-sim: error: {one_line(error)}", file=sys.stderr)
        return REFUSED
    except KeyboardInterrupt:
        return STOPPED
    except BrokenPipeError:
        # The reader went away (`arm-sim run | head -1`): stop quietly, as Unix tools do.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return BROKEN_PIPE
    except OSError as error:
        where = f" {error.filename}" if error.filename else ""
        print(one_line(f"arm-sim: error: cannot write{where}: {error.strerror or error}"),
              file=sys.stderr)
        return REFUSED


if __name__ == "__main__":
    exit_as_main(main())
