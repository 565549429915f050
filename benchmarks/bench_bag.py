"""What recording costs: `arm-sim run --bag` against the same run unrecorded, and how many
messages per second `arm-sim record` keeps up with on loopback, side by side with the
rates the node publishes at.

    python benchmarks/bench_bag.py [--seconds 10] [--repeat 3] [--messages 5000] [--domain 58]

Timings are wall-clock on whatever else the machine is running; read them as rough.
"""
from __future__ import annotations

import argparse
import tempfile
import threading
import time
from pathlib import Path

from arm_sim_ros.tools.run.bag import RunBag, steps_per_publish
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator


def offline_run(scene, seconds, recorder=None) -> float:
    """Wall seconds to simulate `seconds`, with `recorder` called as `arm-sim run` calls it."""
    sim = Simulator(scene)
    start = time.perf_counter()
    if recorder is not None:
        recorder.start(sim)
    sim.run(seconds, recorder.step if recorder is not None else None)
    if recorder is not None:
        recorder.finish(sim)
    return time.perf_counter() - start


def offline_table(seconds: float, repeat: int) -> list[str]:
    """Best of `repeat` runs each: the least disturbed by other work on the machine."""
    scene = load_scene("release").replace(step_size=0.001)
    bare = min(offline_run(scene, seconds) for _ in range(repeat))
    rows = [f"{'arm-sim run, h = 1 ms, ' + format(seconds, 'g') + ' s simulated':44s}"
            f"{'wall s':>8s}{'RTF':>9s}{'µs / JointState':>17s}",
            f"{'no bag':44s}{bare:8.3f}{seconds / bare:9.0f}{'-':>17s}"]
    with tempfile.TemporaryDirectory() as tmp:
        # Warm up: rosbags generates its serialiser on first use.
        offline_run(scene, 0.1, RunBag(Path(tmp) / "warm", steps_per_publish(0.001, 100.0)))
        for rate in (100.0, 1000.0):
            steps = steps_per_publish(0.001, rate)
            wall = min(offline_run(scene, seconds, RunBag(Path(tmp) / f"bag{rate:g}-{k}", steps))
                       for k in range(repeat))
            per_message = (wall - bare) / (seconds * rate) * 1e6
            rows.append(f"{'--bag --publish-rate ' + format(rate, 'g'):44s}{wall:8.3f}"
                        f"{seconds / wall:9.0f}{per_message:17.1f}")
    return rows


def record_throughput(messages: int, domain: int) -> tuple[float, int]:
    """Messages/s from a loopback publisher written into a bag by the recorder."""
    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic

    from arm_sim_ros.node.wire import messages as wire
    from arm_sim_ros.tools.wire.record import DEFAULT_TOPICS, record
    from arm_sim_ros.tools.signals import StopOnSignals

    publisher = wire.make_participant(domain, wire.LOOPBACK_CONFIG)
    listener = wire.make_participant(domain, wire.LOOPBACK_CONFIG)
    writer = DataWriter(publisher, Topic(publisher, "rt/joint_states", wire.JointState),
                        qos=wire.default_qos(wire.JointState))
    stop, counts = StopOnSignals(), {}
    with tempfile.TemporaryDirectory() as tmp:
        thread = threading.Thread(target=lambda: counts.update(
            record(Path(tmp) / "bag", dict(DEFAULT_TOPICS), listener, stop=stop)))
        thread.start()
        while not wire.matched(writer):
            time.sleep(0.01)
        sample = wire.JointState(name=["shoulder_joint", "elbow_joint"], position=[0.1, 0.2],
                                 velocity=[0.3, 0.4], effort=[0.5, 0.6])
        start = time.perf_counter()
        for k in range(messages):
            sample.header.stamp.nanosec = k
            writer.write(sample)
        writer.wait_for_acks(60_000_000_000)
        stop.requested = True
        thread.join()
        elapsed = time.perf_counter() - start
    return messages / elapsed, counts.get("/joint_states", 0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--messages", type=int, default=5000)
    parser.add_argument("--domain", type=int, default=58)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    print("\n".join(offline_table(args.seconds, args.repeat)))
    rate, written = record_throughput(args.messages, args.domain)
    print()
    print(f"{'arm-sim record, JointState on loopback':44s}{'msgs/s':>10s}{'written':>9s}")
    print(f"{'recorder (publisher as fast as it can)':44s}{rate:10.0f}{written:9d}")
    print(f"{'node at publish_rate 100 (default)':44s}{100:10d}{'':>9s}")
    print(f"{'node at publish_rate 1000':44s}{1000:10d}{'':>9s}")


if __name__ == "__main__":
    main()
