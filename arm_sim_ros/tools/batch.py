"""`arm-sim batch`: many arms at once (physics/batch.py) and the throughput it reaches."""
from __future__ import annotations

import os
from math import isfinite

from ..physics.batch import throughput
from ..usage import UsageError
from .arguments import add_scene_arguments, scene_from_args
from .progress import Progress


MAX_THREADS = 256
BYTES_PER_ARM = 250     # peak resident memory per arm, measured at 1e6 arms (212 MB)


def usable_memory() -> int:
    """Half the machine's physical memory: a batch must not push it into swap."""
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") // 2
    except (ValueError, OSError, AttributeError):
        return 4 * 2**30


def cmd_batch(args) -> int:
    scene = scene_from_args(args)
    if args.tolerance is not None and scene.tolerance:
        raise UsageError(f"--tolerance {args.tolerance}: a batch steps every arm by the same "
                         "equal sub-steps (the stability plan's), so it cannot honour a "
                         "tolerance; give --tolerance 0, or run one arm with `arm-sim run`")
    if args.count < 1 or not 1 <= args.threads <= MAX_THREADS:
        raise UsageError(f"--count must be at least 1 and --threads from 1 to {MAX_THREADS}")
    if args.seed < 0:
        raise UsageError(f"--seed {args.seed} must be a non-negative integer")
    memory = args.count * BYTES_PER_ARM
    if memory > usable_memory():
        raise UsageError(f"--count {args.count} needs about {memory / 2**30:.3g} GiB "
                         f"({BYTES_PER_ARM} bytes an arm); this machine has "
                         f"{usable_memory() / 2**30:.3g} GiB to spare: use a smaller --count")
    if not (isfinite(args.duration) and args.duration > 0):
        raise UsageError(f"--duration {args.duration:g} must be a positive number of seconds")
    steps = scene.steps_for(args.duration)
    with Progress(steps * scene.step_size, f"arm-sim batch {scene.name}") as progress:
        r = throughput(scene, args.count, steps, args.threads, args.seed,
                       lambda done: progress.update(done * scene.step_size))
    print(f"scene {scene.name}: {r['arms']} arms x {r['steps']} RK4 steps of {scene.step_size:g} s "
          f"on {r['threads']} thread(s) in {r['seconds']:.3f} s wall")
    print(f"throughput {r['arm_steps_per_s'] / 1e6:.2f} M arm-steps/s; "
          f"non-finite arms {r['non_finite_arms']}; "
          f"max |batch - single-arm RK4| on 3 arms {r['max_diff_vs_single_arm']:.1e}")
    return 0


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("batch", help="simulate many arms at once (one compiled call; "
                                            "numpy without numba) and report throughput")
    add_scene_arguments(p)
    p.add_argument("--count", type=int, default=100_000, help="number of arms (default 100000)")
    p.add_argument("--duration", type=float, default=0.5, help="simulated seconds (default 0.5)")
    p.add_argument("--threads", type=int, default=1, help="threads stepping chunks (default 1)")
    p.add_argument("--seed", type=int, default=0, help="seed of the initial-pose spread")
    p.set_defaults(func=cmd_batch)
