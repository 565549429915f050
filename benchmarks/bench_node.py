"""Cost of the arm_sim node's tick on the dds transport, and its free-running real-time factor.

Targets (issue 3): one tick at 1 kHz physics and 1 kHz publishing <= 200 us (<= 20 % of a
core); free-running real-time factor >= 100 at step 1 ms publishing every 10 ms of simulated
time. Loopback only, on its own DDS domain. Timings on a shared machine are noisy: read the
median and compare rows of one run, not runs.

    python benchmarks/bench_node.py [--ticks 5000] [--seconds 20]
"""
from __future__ import annotations

import argparse
import logging
import os
import statistics
import subprocess
import sys
import time

from arm_sim_ros.node import core as node_core
from arm_sim_ros.node.wire import messages as msg
from arm_sim_ros.node.transports.dds import DdsArmSimNode

DOMAIN = 39
CONFIG = msg.loopback_config(f"arm_sim_bench_node_{os.getpid()}")  # meets only its own peers
SUBSCRIBER = """
import sys, time
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from arm_sim_ros.node.wire import messages as msg
p = msg.make_participant({domain}, {config!r})
r = DataReader(p, Topic(p, "rt/joint_states", msg.JointState), qos=msg.default_qos(msg.JointState))
print("ready", flush=True)
while sys.stdin.readline():   # the benchmark closes stdin when it is done
    pass
"""


class Quiet:
    def info(self, text): pass
    def warning(self, text): pass
    def error(self, text): print(text, file=sys.stderr)


def start_node(**parameters) -> DdsArmSimNode:
    return DdsArmSimNode(parameters, domain_id=DOMAIN, config=CONFIG, log=Quiet())


def time_ticks(tick, ticks: int) -> list:
    for _ in range(200):  # warm-up: first writes build type information
        tick()
    samples = []
    for _ in range(ticks):
        t0 = time.perf_counter()
        tick()
        samples.append(time.perf_counter() - t0)
    return samples


def in_process_reader():
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    p = msg.make_participant(DOMAIN, CONFIG)
    return p, DataReader(p, Topic(p, "rt/joint_states", msg.JointState),
                         qos=msg.default_qos(msg.JointState))


def other_process_reader():
    process = subprocess.Popen([sys.executable, "-c", SUBSCRIBER.format(domain=DOMAIN, config=CONFIG)],
                               stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    process.stdout.readline()
    return process


def wait_matched(node, count):
    deadline = time.monotonic() + 10
    while msg.matched(node.joint_state_writer) < count:
        if time.monotonic() > deadline:
            raise SystemExit("the subscriber was not discovered on loopback")
        time.sleep(0.01)


def tick_rows(ticks: int) -> list:
    one_khz = dict(step_size=0.001, publish_rate=1000.0)
    node = start_node(**one_khz)
    core = node_core.ArmSimCore(node.core.config, Quiet())
    rows = [("node core alone (no transport)", time_ticks(core.tick, ticks)),
            ("dds, no subscriber", time_ticks(node.tick, ticks))]
    keep = in_process_reader()
    wait_matched(node, 1)
    rows.append(("dds, subscriber in this process", time_ticks(node.tick, ticks)))
    process = other_process_reader()
    wait_matched(node, 2)
    rows.append(("dds, + subscriber in another process", time_ticks(node.tick, ticks)))
    process.stdin.close()
    process.wait()
    del keep
    node.close()
    return rows


def paced_cpu_share(seconds: float) -> tuple:
    """CPU time over wall time of the real spin loop at 1 kHz ticks, real time."""
    node = start_node(step_size=0.001, publish_rate=1000.0, real_time_factor=1.0)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    node.spin(seconds)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    late = node.core.late_ticks
    node.close()
    return cpu / wall, seconds / wall, late


def free_running(seconds: float, publish_rate: float, subscriber: bool) -> tuple:
    """Simulated seconds per wall second, and per CPU second of this process (what an
    uncontended core would give; the machine is shared)."""
    node = start_node(step_size=0.001, publish_rate=publish_rate, real_time_factor=0.0)
    process = other_process_reader() if subscriber else None
    if process:
        wait_matched(node, 1)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    node.spin(seconds)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    if process:
        process.stdin.close()
        process.wait()
    node.close()
    return seconds / wall, seconds / cpu


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=5000)
    parser.add_argument("--seconds", type=float, default=20.0, help="simulated s per free run")
    args = parser.parse_args(argv)
    logging.disable(logging.WARNING)

    print("One tick = 1 RK4 step of 1 ms + JointState published (1 kHz physics, 1 kHz publishing)")
    print(f"{'configuration':40s} {'median us':>10s} {'mean us':>9s} {'p99 us':>8s} "
          f"{'core @1kHz':>11s} {'target':>8s}")
    for name, samples in tick_rows(args.ticks):
        us = sorted(s * 1e6 for s in samples)
        mean = statistics.fmean(us)
        print(f"{name:40s} {statistics.median(us):10.1f} {mean:9.1f} "
              f"{us[int(0.99 * len(us))]:8.1f} {mean / 10:10.1f}% {'<= 200':>8s}")

    share, rtf, late = paced_cpu_share(3.0)
    print(f"\nReal spin loop, 1 kHz ticks paced to real time for 3 s: process CPU "
          f"{100 * share:.1f} % of a core (target <= 20 %), real-time factor {rtf:.3f}, "
          f"late ticks {late}")

    print(f"\nFree-running (real_time_factor 0), step 1 ms, {args.seconds:g} s simulated")
    print(f"{'publishing':46s} {'RTF (wall)':>11s} {'RTF (CPU)':>10s} {'target':>8s}")
    for rate, label in ((100.0, "every 10 ms"), (1000.0, "every 1 ms")):
        for subscriber in (False, True):
            name = f"{label}, {'a subscriber in another process' if subscriber else 'no subscriber'}"
            wall, cpu = free_running(args.seconds, rate, subscriber)
            print(f"{name:46s} {wall:11.0f} {cpu:10.0f} {'>= 100' if rate == 100.0 else '':>8s}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
