"""Soak: 10^7 simulator steps across long, fast and stiff runs, then a long node run on DDS
with a command flood; finiteness, energy drift and resident memory before and after; then a
node spinning in real time with a Rerun recording open while a client changes its live
parameters (every live one, good and hostile values) 200 times a second: threads, RSS,
JointState and replies per window, and the time to answer a set.

Not a test: wall times depend on what else the machine runs.

    python benchmarks/bench_soak.py [--scale 1.0] [--node-seconds 1800]
                                    [--changes-seconds 60] [--changes-rate 200] [--only changes]
"""
from __future__ import annotations

import argparse
import logging
import math
import random
import time

from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator

CHECK_EVERY = 1000          # energy residual sampled every this many steps


def rss_mb() -> float:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return math.nan


def soak(label, scene, steps):
    sim = Simulator(scene)
    before, worst, start = rss_mb(), 0.0, time.perf_counter()
    for done in range(0, steps, CHECK_EVERY):
        for _ in range(min(CHECK_EVERY, steps - done)):
            sim.step()
        worst = max(worst, abs(sim.residual()))
    wall = time.perf_counter() - start
    finite = all(math.isfinite(v) for v in sim.state) and not sim.refused_steps
    scale = max(abs(sim.initial_energy), 1.0)
    print(f"{label:34s} {steps:9d} {sim.time:9.0f} {sim.substeps:5d} {wall:8.1f} "
          f"{wall / steps * 1e6:7.2f} {worst:10.2e} {worst / scale:9.1e} {str(finite):>6s} "
          f"{before:7.1f} {rss_mb():7.1f}")
    return steps


def simulator_soak(scale: float) -> None:
    print("simulator soak: 10^7 steps in all (x scale); drift = max |E - E0 - W + loss| sampled "
          f"every {CHECK_EVERY} steps; RSS MB before/after each run")
    print(f"{'run':34s} {'steps':>9s} {'sim s':>9s} {'sub':>5s} {'wall s':>8s} {'us/step':>7s} "
          f"{'drift J':>10s} {'rel':>9s} {'finite':>6s} {'RSS0':>7s} {'RSS1':>7s}")
    release = load_scene("release").replace(step_size=1e-3)
    hour = round(3600 * scale / 1e-3)
    total = soak(f"release, {3600 * scale:g} s at h = 1 ms", release, hour)
    total += soak(f"spin qd0 = (100, -100), {3600 * scale:g} s",
                  release.replace(initial_velocities=(100.0, -100.0)), hour)
    stiff = load_scene("damped_release").replace(damping=50.0, step_size=0.01,
                                                 initial_velocities=(3.0, -3.0))
    total += soak("d = 50 at h = 10 ms (sub-stepped)", stiff, round(1e7 * scale) - total)
    print(f"total steps {total}")


def node_soak(seconds: float) -> None:
    from arm_sim_ros.node.wire import messages as msg
    from arm_sim_ros.node.transports.dds import DdsArmSimNode

    domain = 79
    node = DdsArmSimNode({"real_time_factor": 0.0, "damping": 0.5}, domain_id=domain,
                         config=msg.LOOPBACK_CONFIG, log=logging.getLogger("soak"))
    peer = msg.make_participant(domain, msg.LOOPBACK_CONFIG)
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    writer = DataWriter(peer, Topic(peer, "rt/joint_torque_commands", msg.Float64MultiArray),
                        qos=msg.default_qos(msg.Float64MultiArray))
    reader = DataReader(peer, Topic(peer, "rt/joint_states", msg.JointState),
                        qos=msg.default_qos(msg.JointState))
    while not msg.matched(writer):
        time.sleep(0.01)
    rng, hostile = random.Random(6), ([math.nan, 0.0], [math.inf, 1.0], [1.0], [], [1e308, 0.0])
    sent_bad = received = non_finite = 0
    ticks = round(seconds * node.core.config.values["publish_rate"])
    before, start = rss_mb(), time.perf_counter()
    for tick in range(ticks):
        if tick % 10 == 0:       # a burst of 9 hostile commands and one good one every 10 ticks
            for _ in range(9):
                writer.write(msg.Float64MultiArray(data=list(rng.choice(hostile))))
            writer.write(msg.Float64MultiArray(data=[rng.uniform(-5, 5), rng.uniform(-2, 2)]))
            sent_bad += 9
        node.tick()
        for sample in reader.take(N=100):
            if isinstance(sample, msg.JointState):
                received += 1
                non_finite += not all(math.isfinite(v) for v in
                                      sample.position + sample.velocity + sample.effort)
    wall = time.perf_counter() - start
    time.sleep(0.2)
    node.take_commands()
    core = node.core
    print(f"\nnode soak on DDS (loopback, domain {domain}): {seconds:g} s simulated, {ticks} ticks")
    print(f"{'wall s':>8s} {'ticks/s':>8s} {'published':>9s} {'received':>9s} {'non-finite':>10s} "
          f"{'bad sent':>8s} {'refused':>8s} {'RSS0 MB':>8s} {'RSS1 MB':>8s}")
    print(f"{wall:8.1f} {ticks / wall:8.0f} {ticks:9d} {received:9d} {non_finite:10d} "
          f"{sent_bad:8d} {core.refused_commands:8d} {before:8.1f} {rss_mb():8.1f}")
    node.close()


def threads() -> int:
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("Threads:"))


# Every parameter that may change while the node runs gets its value now, one nearby and
# hostile ones (refused: a transaction that changes nothing). These get the hostile ones only:
# a new file or viewer per change, a stopped timer, a JointState rate the table measures;
# and of those only ones the node refuses (a real_time_factor of 1e200 runs as fast as it
# can, as 0 does; any text is a viewer address to try).
HOSTILE = [math.nan, math.inf, 1e200, 5e-324, -1.0, "nonsense"]
HOSTILE_ONLY = ("rerun_path", "rerun_spawn", "rerun_connect", "lockstep", "publish_rate",
                "real_time_factor")
REFUSED_ONLY = {"real_time_factor": [math.nan, math.inf, 5e-324, 1e-12, -1.0, "nonsense"],
                "rerun_connect": [math.nan, 1e200, -1.0]}


def nearby(value):
    """A value next to a parameter's value now (numbers x 1.1, 0.1 for a zero)."""
    if isinstance(value, bool) or isinstance(value, str):
        return value
    if isinstance(value, (int, float)):
        return value * 1.1 if value else 0.1
    if value and all(isinstance(v, (int, float)) for v in value):
        return [v * 1.1 if v else 0.1 for v in value]
    return value


def live_changes(values: dict) -> list:
    """[(name, [values])] of every parameter that changes live (node/params/parameters.py)."""
    from arm_sim_ros.node.params.parameters import PARAMETERS, START
    changes = []
    for spec in PARAMETERS:
        if spec.when == START:
            continue
        now = values[spec.name]
        good = [] if spec.name in HOSTILE_ONLY or now is None else [now, nearby(now)]
        changes.append((spec.name, good + REFUSED_ONLY.get(spec.name, HOSTILE)))
    return changes


def wire(value):
    """(ParameterType, value) of a Python value."""
    from arm_sim_ros.node.services.parameter_services import (BOOL, DOUBLE, DOUBLE_ARRAY,
                                                              STRING, STRING_ARRAY)
    if isinstance(value, bool):
        return BOOL, value
    if isinstance(value, str):
        return STRING, value
    if isinstance(value, (int, float)):
        return DOUBLE, float(value)
    return (STRING_ARRAY, list(value)) if value and isinstance(value[0], str) else (
        DOUBLE_ARRAY, [float(v) for v in value])


def changes_soak(seconds: float, rate: float, window: float = 5.0, record: bool = True) -> None:
    """A node spinning as arm_sim_node spins it (real time, 100 Hz, recording to a .rrd or
    not) while a client sends set_parameters at `rate`/s over every live parameter; one
    row per `window` s of wall time, then one summary row."""
    import tempfile
    import threading
    from pathlib import Path

    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    from arm_sim_ros.node.wire import messages as msg
    from arm_sim_ros.node.transports import dds_service_types as t
    from arm_sim_ros.node.transports.dds import DdsArmSimNode
    from arm_sim_ros.node.transports.dds_services import cs_id, endpoint_qos, to_value

    domain, folder = 78, Path(tempfile.mkdtemp(prefix="arm_sim_soak_"))
    node = DdsArmSimNode({"damping": 0.5, "rerun_path": str(folder / "soak.rrd") if record else ""},
                         domain_id=domain, config=msg.LOOPBACK_CONFIG,
                         log=logging.getLogger("soak.changes"))
    logging.getLogger("soak.changes").setLevel(logging.CRITICAL)   # refusals by the thousand
    changes = live_changes(node.core.config.values)
    peer = msg.make_participant(domain, msg.LOOPBACK_CONFIG)
    ids = f"clientid={cs_id(peer.guid.bytes, 1)};"
    request = DataWriter(peer, Topic(peer, "rq/arm_sim/set_parametersRequest",
                                     t.SetParametersRequest),
                         qos=endpoint_qos(t.SetParametersRequest, 1000, ids))
    replies = DataReader(peer, Topic(peer, "rr/arm_sim/set_parametersReply",
                                     t.SetParametersResponse),
                         qos=endpoint_qos(t.SetParametersResponse, 1000, ids))
    states = DataReader(peer, Topic(peer, "rt/joint_states", msg.JointState),
                        qos=msg.default_qos(msg.JointState, depth=1000))
    while not (msg.matched(request) and msg.matched(replies) and msg.matched(states)):
        time.sleep(0.01)
    spinner = threading.Thread(target=lambda: node.spin(seconds + 2 * window))
    spinner.start()
    sent_at, latencies, counts, done = {}, [], {"states": 0, "replies": 0, "refused": 0}, []

    def take_replies():           # its own thread: a reply's latency, to the millisecond
        while not done:
            for reply in replies.take(N=1000):
                if isinstance(reply, t.SetParametersResponse):
                    latencies.append(time.monotonic() - sent_at.pop(reply.seq, math.nan))
                    counts["replies"] += 1
                    counts["refused"] += not reply.results[0].successful
            time.sleep(0.0005)

    taker = threading.Thread(target=take_replies)
    taker.start()
    guid, seq, rng = request.get_instance_handle() & ((1 << 64) - 1), 0, random.Random(3)
    print(f"\nlive parameter changes on DDS: {rate:g}/s for {seconds:g} s over {len(changes)} "
          f"live parameters, the node {'recording to a .rrd' if record else 'not recording'}, "
          "publish_rate 100 in real time")
    print(f"{'wall s':>6s} {'threads':>7s} {'RSS MB':>7s} {'JointState/s':>12s} "
          f"{'replies/s':>9s} {'refused':>7s}")
    start = next_row = time.monotonic()
    first, warm = (threads(), rss_mb()), None      # at the start; after the first window
    total_states = 0
    while (now := time.monotonic()) - start < seconds:
        name, values = rng.choice(changes)
        seq += 1
        sent_at[seq] = time.monotonic()
        request.write(t.SetParametersRequest(guid=guid, seq=seq, parameters=[
            t.Parameter(name, to_value(*wire(rng.choice(values))))]))
        arrived = sum(isinstance(s, msg.JointState) for s in states.take(N=1000))
        counts["states"] += arrived
        total_states += arrived
        if now >= next_row:
            span = window if now > start else 1.0
            print(f"{now - start:6.0f} {threads():7d} {rss_mb():7.1f} "
                  f"{counts['states'] / span:12.0f} {counts['replies'] / span:9.0f} "
                  f"{counts['refused']:7d}", flush=True)
            counts.update(dict.fromkeys(counts, 0))
            next_row += window
            if warm is None and now - start >= window:
                warm = (threads(), rss_mb(), seq)
        time.sleep(max(0.0, start + seq / rate - time.monotonic()))
    wall = time.monotonic() - start
    time.sleep(0.5)
    # spin() ends at a simulated time, and a node held (an accepted value it cannot integrate:
    # until a reset or restart) stands still: move its clock past the end
    node.core._elapsed_before_reset_ns += round((seconds + 2 * window) * 1e9)
    done.append(True)
    taker.join()
    last = (threads(), rss_mb())
    spinner.join()
    node.close()
    answered = sorted(x for x in latencies if x == x)
    p50, p99 = (answered[int(q * (len(answered) - 1))] * 1e3 for q in (0.5, 0.99))
    print(f"summary: {seq} sets sent, {len(answered)} answered; threads {first[0]}, "
          f"{warm[0]} after {warm[2]} sets, {last[0]} after {seq}; RSS {first[1]:.1f}, "
          f"{warm[1]:.1f} after {warm[2]} sets, {last[1]:.1f} MB after {seq} "
          f"({(last[1] - warm[1]) * 1024 / (seq - warm[2]):.2f} kB per set since); JointState "
          f"{total_states / wall:.0f}/s; answer latency p50 {p50:.1f} ms, p99 {p99:.1f} ms, "
          f"max {answered[-1] * 1e3:.1f} ms")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scale", type=float, default=1.0, help="fraction of the 10^7 steps")
    parser.add_argument("--node-seconds", type=float, default=1800.0)
    parser.add_argument("--changes-seconds", type=float, default=60.0)
    parser.add_argument("--changes-rate", type=float, default=200.0)
    parser.add_argument("--only", choices=("simulator", "node", "changes"))
    args = parser.parse_args()
    if args.only in (None, "simulator"):
        simulator_soak(args.scale)
    if args.only in (None, "node"):
        node_soak(args.node_seconds)
    if args.only in (None, "changes"):
        changes_soak(args.changes_seconds, args.changes_rate, record=False)
        changes_soak(args.changes_seconds, args.changes_rate)


if __name__ == "__main__":
    main()
