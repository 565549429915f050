"""`arm-sim sweep SCENE --vary KEY=SPEC ... -o OUT.csv`: many runs of a scene, one row each.

Grids (lists, lin:, log:, range:) over any scene key form their product; distributions
(uniform:, normal:, lognormal:, integers:) are drawn --samples times at each grid point,
sample i from its own generator of (--seed, i). The table (OUT.csv) is the same, byte for
byte, on one process, every core (the default) or a Dask cluster (--scheduler), in any
order and on a re-run; beside it go OUT.png (a heat map over two grid keys, else the
distributions) and OUT.json (what the sweep was, and its wall time, which the table leaves
out). Ctrl-C writes the samples done; --resume runs the rest.
"""
from __future__ import annotations

import sys

from ...outputs import check_output, claim_output, clear_output
from ...usage import DONE, FAULT, STOPPED
from ..arguments import add_scene_arguments, scene_from_args
from ..progress import Progress
from ..signals import StopOnSignals
from .api import make_sweep
from .run import execute
from .summary import describe
from . import table

SPEC_HELP = ("SPEC: a list (0.2,0.5,1.0; ';' between values that hold commas: 0,0;90deg,0), "
             "a grid lin:A:B:N or log:A:B:N (N values from A to B), whole numbers range:A:B[:STEP] "
             "(below B), or a distribution drawn per sample: uniform:A:B, normal:MEAN:SD, "
             "lognormal:MEDIAN:S (S: the spread of ln x), integers:A:B. A per-joint key takes one "
             "number for both joints; KEY[0] or KEY[1] varies one joint")


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("sweep", help="run a scene many times over grids and "
                                            "distributions of its keys: one table row each",
                              description=__doc__.splitlines()[0])
    p.add_argument("scene", metavar="SCENE", help="preset name (see `arm-sim scenes`) or a "
                                                  "scene .yaml file")
    add_scene_arguments(p, scene_option=False)
    p.add_argument("--vary", action="append", required=True, metavar="KEY=SPEC",
                   help=f"a scene key the samples vary (repeat for more). {SPEC_HELP}")
    p.add_argument("--samples", type=int, metavar="N",
                   help="draws of the distributions at each grid point (default 100 where a "
                        "--vary is a distribution)")
    p.add_argument("--seed", type=int, default=0, help="seed of every sample's draws "
                                                       "(default 0)")
    p.add_argument("--metrics", metavar="NAME[,NAME...]",
                   help="the controller's figures in the table (default: all of "
                        "peak_torque, overshoot, settle_time, tracking_error, "
                        "steady_state_error)")
    p.add_argument("--after", type=float, default=0.0, metavar="T",
                   help="tracking_error counts from T seconds on (default 0)")
    p.add_argument("--duration", help="simulated seconds of every sample (default: the "
                                      "scene's)")
    p.add_argument("--estimate", choices=("off", "global"),
                   help="off (the default in a sweep: the steps alone) or global (each "
                        "sample's error estimate, at its price)")
    p.add_argument("--workers", type=int,
                   help="local processes (default: the CPU count, where the work is worth "
                        "starting them; 1: this process)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on a Dask cluster, e.g. tcp://127.0.0.1:8786 (pip install "
                        "'arm_sim_ros[fit]')")
    p.add_argument("--plot", metavar="COLUMN[,COLUMN...]",
                   help="the columns the picture shows (default: settle_time, overshoot and "
                        "steady_state_error where there is a set-point, else max_abs_residual)")
    p.add_argument("-o", "--output", required=True, metavar="OUT.csv",
                   help="the table; OUT.png and OUT.json are written beside it")
    p.add_argument("--resume", action="store_true",
                   help="go on from the rows OUT.csv holds (an interrupted sweep's)")
    p.add_argument("--force", action="store_true", help="replace an existing OUT.csv")
    p.set_defaults(func=cmd_sweep)


def cmd_sweep(args) -> int:
    from ...physics.scene import parse_value

    base = scene_from_args(args)
    named = {text.partition("=")[0].strip() for text in args.set or []}
    estimate = args.estimate or (None if {"estimate", "tolerance"} & named or
                                 args.tolerance is not None else "off")
    duration = None if args.duration is None else parse_value("duration", args.duration)
    sweep = make_sweep(base, args.vary, args.samples, args.seed, args.metrics, args.after,
                       duration, estimate)
    if args.workers is not None and args.workers < 1:
        from ...usage import UsageError
        raise UsageError(f"--workers {args.workers} must be at least 1")
    from .picture import check_plot
    check_plot(args.plot, sweep.columns)                            # before the work
    from .pool import connect
    client = connect(args.scheduler) if args.scheduler else None    # before any file
    out = check_outputs(args)
    label = f"arm-sim sweep {base.name}"
    with StopOnSignals() as stop, Progress(sweep.plan.count, label, unit="samples") as progress:
        result = execute(sweep, out, args.resume, args.workers, client, stop, progress)
    picture = None
    if result.complete:
        from .picture import draw
        picture = draw(out, sweep, result.columns, args.plot)
    print(describe(sweep, result, out, picture))
    if not result.complete:
        kept = len(result.columns["index"])
        why = result.lost or f"interrupted ({stop.requested or 'stopped'})"
        print(f"arm-sim: {why}: {kept} of {sweep.plan.count} samples are in {out}; the same "
              "command with --resume runs the rest", file=sys.stderr)
        return FAULT if result.lost else STOPPED
    return DONE


def check_outputs(args):
    """OUT.csv and what goes beside it, checked before any work; claimed unless resumed."""
    out = check_output(args.output, "-o", args.force or args.resume, suffixes=(".csv",))
    for suffix in (table.SIDECAR, table.PICTURE):
        if not args.resume:
            check_output(str(table.beside(out, suffix)), f"-o (its {suffix} beside it)",
                         args.force)
    if args.resume and out.exists():
        return out
    if args.force:
        for path in (out, table.beside(out, table.SIDECAR), table.beside(out, table.PICTURE)):
            clear_output(path)
    claim_output(out, "-o")
    return out
