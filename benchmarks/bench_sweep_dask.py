"""`arm-sim sweep --scheduler` on a Dask LocalCluster: one worker process against two, and
the tables byte for byte.

The sweep (default: the sweeps guide's robustness study, servo_reach with noisy sensors,
a payload, friction and a latency drawn per sample) runs on a LocalCluster of 1 and of 2
worker processes (one thread each), --repeat times each, interleaved; every worker first
runs one sample by itself (client.run), so the kernels are compiled or loaded before the
clock starts. Printed: the wall time of each run, samples/s, the speed-up of 2 workers over
1 (best of the repeats), and whether every table is the same bytes as the first; beside
it, the speed-up the machine itself offers two processes at that moment (a pure-Python
loop on 1 and on 2 processes): on a machine whose other work takes a core, neither can
reach 2x. Timings are wall-clock on whatever else the machine runs: compare side by side.

    python benchmarks/bench_sweep_dask.py [--samples N] [--duration S] [--repeat R]
"""
from __future__ import annotations

import argparse
import logging
import shlex
import time

import distributed

import arm_sim_ros

SCENE = "servo_reach"
SETS = {"sensors.position_noise": "2e-4,2e-4", "sensors.velocity_noise": "2e-3,2e-3"}
VARY = {"payload.mass": "uniform:0.2:1.0", "friction.coulomb": "uniform:0.7:1.3",
        "command_delay": "0;0.002;0.005", "sensors.seed": "integers:0:4294967295"}


def base_scene():
    from arm_sim_ros.physics.scene import load_scene
    return load_scene(SCENE).with_text_overrides([f"{k}={v}" for k, v in SETS.items()])


def warm(duration: float) -> int:
    """One sample in this worker: its kernels compiled (or loaded) before the timing."""
    result = arm_sim_ros.sweep(base_scene(), VARY, samples=1, duration=duration, workers=1)
    return len(result.text)


def timed(workers: int, samples: int, duration: float):
    with distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                  protocol="tcp", host="127.0.0.1", dashboard_address=None,
                                  silence_logs=logging.CRITICAL) as cluster, \
            distributed.Client(cluster) as client:
        client.run(warm, duration)
        started = time.perf_counter()
        result = arm_sim_ros.sweep(base_scene(), VARY, samples=samples, duration=duration,
                                   scheduler=cluster.scheduler_address)
        return time.perf_counter() - started, result


def spin(count: int) -> int:
    total = 0
    for k in range(count):
        total += k * k
    return total


def offered(count: int = 10_000_000) -> float:
    """The speed-up 2 processes get over 1 on a loop of pure Python now, four loops each."""
    from multiprocessing import get_context

    seconds = {}
    for workers in (1, 2):
        started = time.perf_counter()
        with get_context("spawn").Pool(workers) as processes:
            processes.map(spin, [count] * 4)
        seconds[workers] = time.perf_counter() - started
    return seconds[1] / seconds[2]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=256, help="draws per grid point")
    parser.add_argument("--duration", type=float, default=2.0)
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    vary = " ".join(f"--vary {shlex.quote(f'{k}={v}')}" for k, v in VARY.items())
    print(f"arm-sim sweep {SCENE} {' '.join(f'--set {k}={v}' for k, v in SETS.items())} "
          f"{vary} --samples {args.samples} --duration {args.duration:g}")
    print(f"{'workers':>7s} {'wall s':>8s} {'samples/s':>10s}  table")
    best, first = {}, None
    for _ in range(args.repeat):
        for workers in (1, 2):
            seconds, result = timed(workers, args.samples, args.duration)
            first = result.text if first is None else first
            same = "the same bytes" if result.text == first else "DIFFERS"
            count = len(result.columns["index"])
            print(f"{workers:7d} {seconds:8.2f} {count / seconds:10.1f}  {same} "
                  f"({result.counts['ok']} of {count} ok)")
            best[workers] = min(best.get(workers, float("inf")), seconds)
    print(f"speed-up of 2 workers over 1 (best of {args.repeat}): {best[1] / best[2]:.2f}x; "
          f"the machine offers 2 processes {offered():.2f}x now (a pure-Python loop)")


if __name__ == "__main__":
    main()
