"""What an in-process closed loop costs (arm_sim_ros.testing.closed_loop): CPU seconds per run
of a PD at 1 kHz on `release` (h = 1 ms, --seconds of simulated time, estimate off), without
sensors, with the issue's full `sensors` block, and with it under a command_delay; beside
the same rows on another checkout (--base DIR), timed in the same run.

Each tree runs in a worker process of its own (PYTHONPATH = the tree); the workers time
their rows in turns, each row keeping its fastest of --repeat rounds, after one untimed
short run of each (compiled or loaded). The time is the worker's CPU time (one thread):
on a shared machine, less of the other work's than the wall clock. The sensors block:

    seed 7, rate 500 Hz, 4096 counts, noise 1e-4 rad, velocity differences, delay 2 ms

A base tree is a checkout of another commit, e.g.

    git archive <commit> | tar -x -C /tmp/base
    nice python benchmarks/bench_loop.py [--seconds 10] [--repeat 3] [--base /tmp/base]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

HERE = Path(__file__).resolve()
sys.path.insert(0, str(HERE.parent))   # the sibling benchmark scripts

from bench_core import TreeWorker  # noqa: E402  (a worker on another tree)

SENSORS = {"sensors.seed": 7, "sensors.rate": 500.0,
           "sensors.position_resolution": "0.0015339807878856412,0.0015339807878856412",
           "sensors.position_noise": "1e-4,1e-4", "sensors.velocity": "differences",
           "sensors.delay": 0.002}
ROWS = {"no sensors": {"step_size": 0.001},
        "sensors": {"step_size": 0.001, **SENSORS},
        "sensors + command_delay 1 ms": {"step_size": 0.001, **SENSORS, "command_delay": 0.001}}

WORKER = f"""
import sys, time
import arm_sim_ros
from arm_sim_ros.testing.loop import closed_loop
print(arm_sim_ros.__file__, flush=True)
ROWS, seconds = {ROWS!r}, float(sys.argv[1])

def pd(r):
    return (20.0 * (0.5 - r.q[0]) - 2.0 * r.qd[0], 20.0 * (-0.3 - r.q[1]) - 2.0 * r.qd[1])

for overrides in ROWS.values():
    closed_loop(pd, "release", 0.05, overrides=overrides)
for _ in sys.stdin:
    times = []
    for overrides in ROWS.values():
        start = time.process_time()
        closed_loop(pd, "release", seconds, overrides=overrides)
        times.append(time.process_time() - start)
    print(*times, flush=True)
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--base", type=Path, help="another checkout, timed beside this one")
    args = parser.parse_args()
    trees = {"this tree": HERE.parent.parent}
    if args.base is not None:
        trees = {"base": args.base, **trees}
    workers = {name: TreeWorker(tree, WORKER, str(args.seconds)) for name, tree in trees.items()}
    try:
        for _ in range(args.repeat):
            for worker in workers.values():
                worker.run()
    finally:
        for worker in workers.values():
            worker.close()
    print(f"closed_loop, a PD at 1 kHz on release, {args.seconds:g} s at h = 1 ms: CPU s per run, "
          f"the fastest of {args.repeat}")
    print(f"{'row':32s}" + "".join(f"{name:>12s}" for name in workers)
          + (f"{'base / this':>14s}" if len(workers) > 1 else ""))
    for k, row in enumerate(ROWS):
        times = [worker.best[k] for worker in workers.values()]
        print(f"{row:32s}" + "".join(f"{t:12.3f}" for t in times)
              + (f"{times[0] / times[1]:13.2f}x" if len(times) > 1 else ""))
    for name, worker in workers.items():
        print(f"{name}: sensors / no sensors {worker.best[1] / worker.best[0]:.2f}x, with "
              f"command_delay {worker.best[2] / worker.best[0]:.2f}x")


if __name__ == "__main__":
    main()
