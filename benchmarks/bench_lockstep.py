"""A closed loop in lockstep over DDS: ticks per wall second of the node with a Python
controller in another process, beside a bare DDS ping-pong of the same messages between two
Python processes, measured in the same run, idle and with every core kept busy.

Rows (each the best of `--rounds` rounds of `--seconds` s, the rows measured in turn in each
round, after each has answered once):
- ping-pong: a JointState written, answered by another process with a JointState, the
  answer awaited (cyclonedds, loopback): round trips per wall second, the wire's limit;
- lockstep, /clock off and on: the node (dds transport, its own process, lockstep,
  real_time_factor 0) and arm_sim_ros.testing's Controller (a PD law) in a third process,
  answering each state with its stamp: ticks per wall second, as the controller counts them;
- run(): the same through the test fixture's WireArm.run (paused, StepSimulation ticks
  each waiting for its answer), the controller in its own process.
- ros2_control (controller_manager under use_sim_time, lockstep): measured by hand where a
  ROS 2 with ros2_control is sourced; docs/guides/testing.md says how.
`--busy` keeps every core busy with that many spinning processes during a second pass.

    python benchmarks/bench_lockstep.py [--seconds 3] [--rounds 3] [--busy 2]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

HERE = os.path.abspath(__file__)


def config(tag: str) -> str:
    from arm_sim_ros.node.wire import messages as msg
    return msg.loopback_config(tag)


def participant(tag: str, domain: int):
    # a domain of each pass's own: a process keeps one configuration a domain id (messages.py)
    from arm_sim_ros.node.wire import messages as msg
    return msg.make_participant(domain, config(tag))


def endpoints(p, write: str, read: str):
    from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from arm_sim_ros.node.wire import messages as msg
    writer = DataWriter(p, Topic(p, write, msg.JointState), qos=msg.default_qos(msg.JointState))
    reader = DataReader(p, Topic(p, read, msg.JointState), qos=msg.default_qos(msg.JointState))
    ready = WaitSet(p)
    ready.attach(ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any))
    return writer, reader, ready


def state(k: int):
    from arm_sim_ros.node.wire import messages as msg
    return msg.JointState(header=msg.Header(stamp=msg.Time(k // 1000, (k % 1000) * 1000000)),
                          name=["shoulder_joint", "elbow_joint"], position=[0.1, 0.2],
                          velocity=[0.3, 0.4], effort=[0.5, 0.6])


# --- roles, each in a process of its own ---------------------------------------------------

def echo(tag: str, domain: int) -> None:
    """Answer every JointState on rt/ping with one on rt/pong, until stdin closes."""
    from cyclonedds.util import duration
    writer, reader, ready = endpoints(participant(tag, domain), "rt/pong", "rt/ping")
    print("ready", flush=True)
    while True:
        ready.wait(duration(seconds=1))
        for sample in reader.take(N=100):
            if hasattr(sample, "header"):
                writer.write(sample)


class PingPong:
    """This process's end of the ping-pong, its partner in a process of its own."""

    def __init__(self, tag: str, domain: int):
        from arm_sim_ros.node.wire import messages as msg
        self.writer, self.reader, self.ready = endpoints(participant(tag, domain), "rt/ping",
                                                          "rt/pong")
        self.partner = subprocess.Popen([sys.executable, HERE, "--role", "echo", "--tag", tag,
                                         "--domain", str(domain)],
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        self.partner.stdout.readline()
        while not (msg.matched(self.writer) and msg.matched(self.reader)):
            time.sleep(0.01)
        self.k = 0

    def measure(self, seconds: float) -> float:
        from cyclonedds.util import duration
        done, started = 0, time.perf_counter()
        while (elapsed := time.perf_counter() - started) < seconds:
            ping = state(self.k)
            self.writer.write(ping)
            self.k += 1
            while not [s for s in self.reader.take(N=10) if hasattr(s, "header")]:
                if not self.ready.wait(duration(seconds=1)):
                    self.writer.write(ping)    # a second of nothing: lost, sent again
            done += 1
        return done / elapsed

    def close(self) -> None:
        self.partner.kill()
        self.partner.wait()


def controller(domain: int) -> None:
    """A PD Controller answering the node only while a measurement runs: each line on stdin,
    a number of seconds, opens the gate for that long, then prints the rate it answered at.
    Between two the node waits for its answer (lockstep): it takes no CPU from the others."""
    import threading
    from arm_sim_ros.testing.controller import Controller
    target, gate = np.array([0.5, -0.3]), threading.Event()

    def pd(reading):
        gate.wait()
        return 60.0 * (target - reading.q) - 12.0 * reading.qd

    law = Controller(pd, domain).start()
    print("ready", flush=True)
    for line in sys.stdin:
        before, started = law.answered, time.perf_counter()
        gate.set()
        time.sleep(float(line))
        gate.clear()
        print(json.dumps({"rate": (law.answered - before) / (time.perf_counter() - started)}),
              flush=True)


def wire_env(domain: int) -> dict:
    from arm_sim_ros.testing.wire import wire_env as env
    return env(domain)


class Controlled:
    """A controller process on `domain`, and the node it answers (unless `node` is None)."""

    def __init__(self, domain: int, node: list | None):
        env = wire_env(domain)
        self.node = node and subprocess.Popen(
            [sys.executable, "-m", "arm_sim_ros.node.main", "--transport", "dds", "--quiet",
             "--ros-args", *node], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        self.law = subprocess.Popen([sys.executable, HERE, "--role", "controller", "--domain",
                                     str(domain)], stdin=subprocess.PIPE,
                                    stdout=subprocess.PIPE, text=True, env=env)
        self.law.stdout.readline()

    def measure(self, seconds: float) -> float:
        self.law.stdin.write(f"{seconds}\n")
        self.law.stdin.flush()
        return json.loads(self.law.stdout.readline())["rate"]

    def close(self) -> None:
        for process in (self.law, self.node):
            if process:
                process.kill()
                process.wait()


def lockstep_node(clock: bool) -> list:
    return ["-p", "policy:=command", "-p", "gravity:=0.0", "-p", "lockstep:=true", "-p",
            "lockstep_wait:=0.0", "-p", f"publish_clock:={'true' if clock else 'false'}",
            "-p", "estimate:=global"]


class Fixture:
    """WireArm.run with a controller in its own process: ticks per wall second of a run."""

    def __init__(self, domain: int, directory: str):
        from arm_sim_ros.testing.wire import WireArm
        self.arm = WireArm("release", {"policy": "command", "gravity": 0.0},
                           directory=directory, domain_id=domain)
        self.law = Controlled(domain, None)
        self.law.law.stdin.write("1e9\n")              # its gate open for good
        self.law.law.stdin.flush()

    def measure(self, seconds: float) -> float:
        before, started = len(self.arm.heard.states), time.perf_counter()
        self.arm.run(seconds)
        return (len(self.arm.heard.states) - before) / (time.perf_counter() - started)

    def close(self) -> None:
        self.law.close()
        self.arm.close()


def measure(args, domain: int) -> dict:
    """Every row measured in turn, round after round (a slow spell of the machine falls on
    all of them), best of the rounds after a first that warms up."""
    import tempfile
    with tempfile.TemporaryDirectory() as directory:
        tag = f"bench_lockstep_{os.getpid()}_{domain}"
        rows = {"ping-pong (round trips/s)": PingPong(tag, domain),
                "lockstep, /clock off": Controlled(domain + 1, lockstep_node(False)),
                "lockstep, /clock on": Controlled(domain + 2, lockstep_node(True)),
                "run() (fixture)": Fixture(domain + 3, directory)}
        try:
            for name, row in rows.items():       # up: a first answer before any round
                while row.measure(0.5) == 0:
                    pass
            rates = {name: [] for name in rows}
            for _ in range(args.rounds):
                for name, row in rows.items():
                    rates[name].append(row.measure(args.seconds))
        finally:
            for row in rows.values():
                row.close()
    return {name: max(values) for name, values in rates.items()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--busy", type=int, default=os.cpu_count() or 2,
                        help="spinning processes during the busy pass (0: no busy pass)")
    parser.add_argument("--role", help=argparse.SUPPRESS)
    parser.add_argument("--tag", help=argparse.SUPPRESS)
    parser.add_argument("--domain", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.role == "echo":
        echo(args.tag, args.domain)
        return 0
    if args.role == "controller":
        controller(args.domain)
        return 0
    if args.role == "spin":
        while True:
            pass
    passes = {"idle": measure(args, 40)}
    if args.busy:
        spinners = [subprocess.Popen([sys.executable, HERE, "--role", "spin"])
                    for _ in range(args.busy)]
        try:
            passes[f"{args.busy} busy"] = measure(args, 44)
        finally:
            for spinner in spinners:
                spinner.kill()
    print(f"closed loop over DDS, ticks (or round trips) per wall second; best of "
          f"{args.rounds} rounds of {args.seconds:g} s; {os.cpu_count()} cores")
    print(f"{'':30}" + "".join(f"{name:>14}{'x ping':>8}" for name in passes))
    for row in passes["idle"]:
        line = f"{row:30}"
        for values in passes.values():
            pong = values["ping-pong (round trips/s)"]
            line += f"{values[row]:14.0f}{pong / values[row]:8.2f}"
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
