"""The arm_sim node's tick, split, and its free-running real-time factor, on both transports,
beside the physical limit of a write; with `--base DIR`, another checkout's node (main's)
measured in the same run, interleaved, so the ratio between the two is safe to quote.

Each checkout runs in a worker process of its own (PYTHONPATH: the checkout), driven one
measurement at a time, alternately, best of `--repeats`; loopback only, every worker on a
DDS tag of its own (they never meet each other or another run). Rows:
- CPU µs per tick at h = 1 ms publishing every step (`release`, no subscriber), split into
  physics (Simulator.step, and the energy residual the node books every tick), messages
  (the JointState's data, the JointState and Clock built and serialized), writes (the DDS
  write or rclpy publish, serialization left out where it is ours) and the rest (commands,
  services, stamps, schedule: the tick's own Python). CPU time, not wall: the machine is
  shared. The split comes from a run with each piece wrapped (thread CPU time, less the
  wrappers' own cost): read it to a µs or two;
- the free-running real-time factor (real_time_factor 0) publishing every step and at
  100 Hz, for `release`, `stick_slip` and `geared_arm`;
- the process's CPU share of a core at 1 kHz ticks paced to real time;
- the limit: a bare cyclonedds write of a ready JointState (cyclonedds' own serializer, and
  the C write of its ready bytes) and an rclpy publish of a ready JointState.
The rclpy rows need rclpy (ROS 2 sourced); without it they are left out.

    python benchmarks/bench_node.py [--base /path/to/main] [--repeats 5] [--seconds 5]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path

HERE = Path(__file__).resolve()
SCENES = ("release", "stick_slip", "geared_arm")
SPLIT = ("physics", "messages", "writes", "rest")
TICKS = 500          # ticks a round
ROUNDS = 5           # rounds a measurement: the least taken


# --- the worker: one checkout's node, measured on demand ----------------------------------

class Quiet:
    def info(self, text): pass
    def warning(self, text): pass
    def error(self, text): print(text, file=sys.stderr)
    def debug(self, text): pass


class Split:
    """Exclusive CPU time of this thread per bucket of wrapped calls (a call inside another
    counts in its own bucket only). CPU time, not wall: the machine is shared, and a tick
    preempted midway would charge the wait to whatever piece it was in."""

    def __init__(self):
        self.seconds, self.calls, self._inner = defaultdict(float), defaultdict(int), []
        nothing = self.wrap("nothing", lambda: None)
        started = time.thread_time()
        for _ in range(5000):
            nothing()
        whole = (time.thread_time() - started) / 5000
        # what a wrapped call that does nothing is charged (the clock's own cost), and what
        # the wrapper costs its caller besides
        self.inside = self.seconds.pop("nothing") / self.calls.pop("nothing")
        self.outside = whole - self.inside

    def wrap(self, bucket: str, function):
        def timed(*args, **kwargs):
            started = time.thread_time()
            self._inner.append(0.0)
            try:
                return function(*args, **kwargs)
            finally:
                elapsed = time.thread_time() - started
                self.seconds[bucket] += elapsed - self._inner.pop()
                self.calls[bucket] += 1
                if self._inner:
                    self._inner[-1] += elapsed
        return timed

    def split(self, ticks: int, seconds: float) -> dict:
        """µs a tick per bucket, and the rest of `seconds` (the thread's CPU over the ticks),
        each less what the wrappers cost it."""
        parts = {k: (self.seconds[k] - self.inside * self.calls[k]) / ticks * 1e6
                 for k in SPLIT[:3]}
        wrapping = (self.inside + self.outside) * sum(self.calls.values())
        return {**parts, "rest": (seconds - wrapping) / ticks * 1e6 - sum(parts.values())}


class Worker:
    def __init__(self):
        from arm_sim_ros.node.wire import messages as msg
        self.msg, self.domain = msg, 40 + os.getpid() % 150
        self.config = msg.loopback_config(f"arm_sim_bench_node_{os.getpid()}")
        self.rclpy = None
        try:
            import rclpy
            rclpy.init(args=["bench_node", "--ros-args", "--log-level", "error"])
            self.rclpy = rclpy
        except Exception:    # noqa: BLE001 - no ROS 2 here: the rclpy rows are left out
            pass

    def node(self, transport: str, **parameters):
        parameters = {"step_size": 0.001, "publish_rate": 1000.0, "real_time_factor": 0.0,
                      **parameters}
        if transport == "dds":
            from arm_sim_ros.node.transports.dds import DdsArmSimNode
            return DdsArmSimNode(parameters, domain_id=self.domain, config=self.config,
                                 log=Quiet())
        from rclpy.parameter import Parameter
        from arm_sim_ros.node.transports.rclpy_transport import ArmSimNode
        overrides = [Parameter(k, value=v) for k, v in parameters.items()]
        return ArmSimNode(parameter_overrides=overrides)

    def close(self, transport: str, node) -> None:
        node.close() if transport == "dds" else node.destroy_node()

    def tick_of(self, transport: str, node):
        return node.tick if transport == "dds" else node.on_tick

    def handle(self, job: dict) -> dict:
        return getattr(self, job["kind"])(**job["args"])

    def transports(self) -> dict:
        from arm_sim_ros.physics.compiled import build
        return {"transports": ["dds"] + (["rclpy"] if self.rclpy else []),
                "compiled": build.available()}

    def tick(self, transport: str, ticks: int) -> dict:
        """CPU µs per tick of the process (DDS's own threads included), unwrapped; then the
        pieces, from a run with each wrapped; the rest is what the pieces leave of the total."""
        node = self.node(transport)
        tick = self.tick_of(transport, node)
        for _ in range(200):                # warm-up: compile, type information, caches
            tick()
        total = wall = float("inf")
        for _ in range(ROUNDS):             # the least of short rounds: the least disturbed
            started, wall_started = time.process_time(), time.perf_counter()
            for _ in range(ticks):
                tick()
            total = min(total, (time.process_time() - started) / ticks * 1e6)
            wall = min(wall, (time.perf_counter() - wall_started) / ticks * 1e6)
        # the split of the least disturbed wrapped round (the least CPU): its pieces add up
        parts = min((self._split(transport, node, tick, ticks) for _ in range(ROUNDS)),
                    key=lambda split: sum(split.values()))
        self.close(transport, node)
        return {"total": total, "wall": wall, **parts}

    def _split(self, transport: str, node, tick, ticks: int) -> dict:
        """Each piece of the tick wrapped (whichever of them this checkout has: the node's
        message code moved between versions), `ticks` ticks, everything put back."""
        split, core, msg = Split(), node.core, self.msg
        if transport == "dds":
            from arm_sim_ros.node.transports import dds as module
            own = [(w, "write", "writes") for w in (node.joint_state_writer, node.clock_writer)]
            classes = (msg.JointState, msg.Clock)   # built and serialized: messages
        else:
            from arm_sim_ros.node.transports import rclpy_transport as module
            own = [(p, "publish", "writes")
                   for p in (node.joint_state_publisher, node.clock_publisher)]
            classes = ()
        own += [(core.sim, "step", "physics"), (core.sim, "residual", "physics"),
                (core, "joint_state", "messages")]
        for entity, name, bucket in own:         # an instance's own attribute, deleted after
            setattr(entity, name, split.wrap(bucket, getattr(entity, name)))
        names = [(module, name, "messages") for name in (
            "to_joint_state", "_stamp", "Clock", "split_stamp", "joint_state_bytes", "clock_cdr")]
        names.append((module, "write_cdr", "writes"))
        saved = [(owner, name, getattr(owner, name)) for owner, name, _ in names
                 if hasattr(owner, name)]
        kept = [(c, a, c.__dict__.get(a)) for c in classes for a in ("serialize", "__init__")]
        for (owner, name, bucket), (_, _, value) in zip(
                [n for n in names if hasattr(n[0], n[1])], saved):
            setattr(owner, name, split.wrap(bucket, value))
        for cls, attribute, _ in kept:
            setattr(cls, attribute, split.wrap("messages", getattr(cls, attribute)))
        started = time.thread_time()
        try:
            for _ in range(ticks):
                tick()
        finally:
            seconds = time.thread_time() - started
            for owner, name, value in saved:
                setattr(owner, name, value)
            for cls, attribute, value in kept:
                if value is None:
                    delattr(cls, attribute)
                else:
                    setattr(cls, attribute, value)
            for entity, name, _ in own:
                delattr(entity, name)
        return split.split(ticks, seconds)

    def free(self, transport: str, scene: str, rate: float, seconds: float) -> dict:
        """Simulated seconds per CPU second of the process (what a core of its own would
        give: the machine is shared) and per wall second, free-running, after a warm-up
        simulated second (the compiled modes loaded)."""
        node = self.node(transport, scene=scene, publish_rate=rate)
        self._spin(transport, node, 1.0)
        cpu, wall, simulated = time.process_time(), time.perf_counter(), node.core.sim.time
        # From where the warm-up ended, not from 1 s: one rclpy spin_once can run past
        # 1 + seconds (geared_arm at rest, 100 Hz), which left the window empty (0.0).
        self._spin(transport, node, self._elapsed(node) + seconds)
        simulated = node.core.sim.time - simulated
        rtf = {"rtf": simulated / (time.process_time() - cpu),
               "wall": simulated / (time.perf_counter() - wall)}
        self.close(transport, node)
        return rtf

    def paced(self, transport: str, seconds: float) -> dict:
        """The process's CPU share of a core at 1 kHz ticks paced to real time."""
        node = self.node(transport, real_time_factor=1.0)
        self._spin(transport, node, 0.2)
        cpu, wall = time.process_time(), time.perf_counter()
        self._spin(transport, node, 0.2 + seconds)
        share = (time.process_time() - cpu) / (time.perf_counter() - wall)
        self.close(transport, node)
        return {"share": share}

    @staticmethod
    def _elapsed(node) -> float:
        """Simulated seconds since the node started (what _spin's `until` counts)."""
        return (node.core.stamp_ns() - node.core.start_stamp_ns) / 1e9

    def _spin(self, transport: str, node, until: float) -> None:
        if transport == "dds":
            node.spin(until)
            return
        end_ns = round(until * 1e9)
        while node.core.stamp_ns() - node.core.start_stamp_ns < end_ns:
            self.rclpy.spin_once(node, timeout_sec=0.1)

    def limit(self, transport: str, count: int) -> dict:
        """µs per write of one ready JointState, as the library offers it."""
        if transport == "dds":
            from cyclonedds.idl import IdlStruct
            from cyclonedds.pub import DataWriter
            from cyclonedds.topic import Topic
            msg = self.msg
            participant = msg.make_participant(self.domain, self.config)
            writer = DataWriter(participant, Topic(participant, "rt/bench_limit", msg.JointState),
                                qos=msg.default_qos(msg.JointState))
            message = msg.JointState(header=msg.Header(stamp=msg.Time(1, 2), frame_id=""),
                                     name=["shoulder", "elbow"], position=[0.1, 0.2],
                                     velocity=[0.3, 0.4], effort=[0.5, 0.6])
            generic = IdlStruct.serialize(message)     # cyclonedds' own serializer
            message.serialize = lambda *a, **k: IdlStruct.serialize(message, *a, **k)
            from cyclonedds._clayer import ddspy_write   # the C write under DataWriter.write
            rows = {"write": lambda: writer.write(message),
                    "c_write": lambda: ddspy_write(writer._ref, generic)}
        else:
            from sensor_msgs.msg import JointState
            node = self.rclpy.create_node("bench_limit")
            publisher = node.create_publisher(JointState, "bench_limit", 10)
            message = JointState(name=["shoulder", "elbow"], position=[0.1, 0.2],
                                 velocity=[0.3, 0.4], effort=[0.5, 0.6])
            rows = {"publish": lambda: publisher.publish(message)}
        result = {}
        for name, write in rows.items():
            for _ in range(200):
                write()
            started = time.process_time()
            for _ in range(count):
                write()
            result[name] = (time.process_time() - started) / count * 1e6
        return result


def serve() -> int:
    """The worker's loop: a JSON job a line in, a JSON answer a line out."""
    import logging
    logging.disable(logging.WARNING)
    worker = Worker()
    for line in sys.stdin:
        print(json.dumps(worker.handle(json.loads(line))), flush=True)
    return 0


# --- the parent: workers driven alternately, best of the repeats ---------------------------

class Checkout:
    def __init__(self, label: str, root: Path):
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(
            filter(None, [str(root), os.environ.get("PYTHONPATH", "")])))
        self.label = label
        self.process = subprocess.Popen([sys.executable, str(HERE), "--serve"], env=env,
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        text=True)

    def ask(self, kind: str, **args) -> dict:
        self.process.stdin.write(json.dumps({"kind": kind, "args": args}) + "\n")
        self.process.stdin.flush()
        line = self.process.stdout.readline()
        if not line:
            raise SystemExit(f"bench_node: the {self.label} worker stopped")
        return json.loads(line)

    def close(self) -> None:
        self.process.stdin.close()
        self.process.wait()


def best(checkouts, repeats: int, kind: str, key: str, lowest: bool, **args) -> dict:
    """{label: the best answer of `repeats`}, the checkouts asked in turn each repeat."""
    answers = defaultdict(list)
    for _ in range(repeats):
        for checkout in checkouts:
            answers[checkout.label].append(checkout.ask(kind, **args))
    pick = min if lowest else max
    return {label: pick(found, key=lambda a: a[key]) for label, found in answers.items()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", type=Path, help="another checkout (main's) to measure beside")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=5.0,
                        help="simulated s per free run")
    parser.add_argument("--serve", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve:
        return serve()
    checkouts = [Checkout("this", HERE.parents[1])]
    if args.base:
        checkouts.append(Checkout("base", args.base.resolve()))
    try:
        report(checkouts, args)
    finally:
        for checkout in checkouts:
            checkout.close()
    return 0


def report(checkouts, args) -> None:
    info = {c.label: c.ask("transports") for c in checkouts}
    transports = info["this"]["transports"]
    labels = [c.label for c in checkouts]
    paths = ", ".join(f"{k}: compiled path {v['compiled']}" for k, v in info.items())
    print(f"bench_node: {paths}; transports {', '.join(transports)}; best of {args.repeats}, "
          f"interleaved; load average {os.getloadavg()[0]:.1f}")
    print("\nCPU µs per tick (the process's), h = 1 ms publishing every step (release, no "
          "subscriber); wall µs beside it")
    print(f"{'transport':10s} {'node':6s} {'total':>8s} " + " ".join(f"{k:>9s}" for k in SPLIT)
          + f" {'wall':>8s}" + (f" {'÷ this':>8s}" if len(labels) > 1 else ""))
    for transport in transports:
        rows = best(checkouts, args.repeats, "tick", "total", True, transport=transport,
                    ticks=TICKS)
        for label in labels:
            row = rows[label]
            ratio = f" {row['total'] / rows['this']['total']:8.2f}" if len(labels) > 1 else ""
            print(f"{transport:10s} {label:6s} {row['total']:8.1f} "
                  + " ".join(f"{row[k]:9.1f}" for k in SPLIT) + f" {row['wall']:8.1f}" + ratio)
    print(f"\nFree-running real-time factor (real_time_factor 0), h = 1 ms, {args.seconds:g} s "
          "simulated, no subscriber: per CPU second of the process (per wall second)")
    print(f"{'transport':10s} {'scene':12s} {'publishing':>12s} "
          + " ".join(f"{label:>16s}" for label in labels)
          + (f" {'this ÷ base':>12s}" if len(labels) > 1 else ""))
    for transport in transports:
        for scene in SCENES:
            for rate, what in ((1000.0, "every step"), (100.0, "100 Hz")):
                rows = best(checkouts, args.repeats, "free", "rtf", False, transport=transport,
                            scene=scene, rate=rate, seconds=args.seconds)
                ratio = (f" {rows['this']['rtf'] / rows['base']['rtf']:12.2f}"
                         if len(labels) > 1 else "")
                print(f"{transport:10s} {scene:12s} {what:>12s} " + " ".join(
                    f"{rows[label]['rtf']:8.1f} ({rows[label]['wall']:5.1f})"
                    for label in labels) + ratio)
    print("\nPaced to real time (real_time_factor 1), 1 kHz ticks for 3 s: the process's CPU, "
          "% of a core")
    for transport in transports:
        rows = best(checkouts, args.repeats, "paced", "share", True, transport=transport,
                    seconds=3.0)
        print(f"{transport:10s} " + " ".join(f"{label} {100 * rows[label]['share']:5.1f} %"
                                             for label in labels))
    print("\nThe limit: one ready JointState written from Python, CPU µs")
    for transport in transports:
        key = {"dds": "write", "rclpy": "publish"}[transport]
        answer = best(checkouts[:1], args.repeats, "limit", key, True, transport=transport,
                      count=5000)["this"]
        for name, us in answer.items():
            what = {"write": "cyclonedds DataWriter.write (its own serializer)",
                    "c_write": "cyclonedds' C write of the ready bytes (ddspy_write)",
                    "publish": "rclpy Publisher.publish (rmw_cyclonedds)"}[name]
            print(f"{transport:10s} {what:58s} {us:8.1f}")


if __name__ == "__main__":
    sys.exit(main())
