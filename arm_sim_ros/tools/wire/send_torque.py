"""`arm-sim send-torque TAU1 TAU2`: publish joint_torque_commands on the dds transport, the
way `ros2 topic pub` would where ROS 2 is installed.

The node drops a command that is not repeated within its command_timeout, so by default the
command is repeated at --rate until Ctrl-C or --duration; --once sends it one time.

A node that refuses the commands (beyond its torque_limit) says so on /diagnostics, once a
second: its refused_commands count and why (last_refusal). The sender reads it (Refusals):
the count before it sends, then while it sends, and once after, until the node has taken
what was sent. A count that rose ends the sending: one line saying why, exit code 1.
"""
from __future__ import annotations

import sys
import time
from math import isfinite

from ...interface import COMMAND_TOPIC, DIAGNOSTICS_TOPIC, FLOAT64_MULTI_ARRAY, wrong_type
from ...node.commands.intake import COMMAND_POLICIES
from ...usage import UsageError


WAIT = 30.0     # a node started at the same time, or after, on a loaded machine: found
DIAGNOSTICS_WAIT = 2.5   # s: the node publishes /diagnostics once a wall second


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "send-torque", help="publish [tau1, tau2] N m to joint_torque_commands (dds transport)",
        usage="arm-sim send-torque [options] TAU1 TAU2")
    # Counted here, not by argparse, whose complaint for one torque names no second one.
    parser.add_argument("torques", nargs="*", type=float, metavar="TAU1 TAU2",
                        help="shoulder and elbow torque, N m (two numbers)")
    parser.add_argument("--rate", type=float, default=10.0, help="repeats per second (default 10)")
    parser.add_argument("--duration", type=float, help="stop after this many seconds")
    parser.add_argument("--once", action="store_true", help="send one command and exit")
    parser.add_argument("--topic", default="joint_torque_commands", help="ROS topic name")
    parser.add_argument("--wait", type=float, default=WAIT,
                        help=f"seconds to wait for the node to be discovered (default {WAIT:g}): "
                             "it may start after this")
    parser.set_defaults(func=cmd_send_torque)


def cmd_send_torque(args) -> int:
    if len(args.torques) != 2:
        given = f"got {len(args.torques)}" + (f" ({' '.join(f'{t:g}' for t in args.torques)})"
                                              if args.torques else "")
        raise UsageError(f"send-torque needs two torques, TAU1 TAU2 (shoulder and elbow, N m), "
                         f"e.g. `arm-sim send-torque 0.5 0.0`; {given}")
    for name, value in (("--rate", args.rate), ("--wait", args.wait)):
        if not (isfinite(value) and value > 0):
            raise UsageError(f"{name} {value} must be a positive number")
    if args.duration is not None and not (isfinite(args.duration) and args.duration >= 0):
        raise UsageError(f"--duration {args.duration} must be a finite number >= 0")
    bad = [f"{t:g}" for t in args.torques if not isfinite(t)]
    if bad:              # the node would refuse it: said here, before joining the network
        raise UsageError(f"send-torque {' '.join(f'{t:g}' for t in args.torques)}: "
                         f"{', '.join(bad)} is not a torque (finite N m)")
    from ...node.wire.one_cyclone import require_cyclonedds

    require_cyclonedds("arm-sim send-torque")
    from ...node.wire.messages import check_topic_name

    check_topic_name(args.topic, "--topic")   # before joining the network
    if problem := wrong_type(args.topic, FLOAT64_MULTI_ARRAY):
        raise UsageError(f"--topic {args.topic}: {problem} (the arm_sim node's topic); "
                         f"send-torque publishes {FLOAT64_MULTI_ARRAY} torques: leave --topic "
                         f"out for {COMMAND_TOPIC}")
    publisher = TorquePublisher(args.topic)
    if not publisher.wait_for_subscriber(args.wait):
        others = publisher.other_types()
        why = (f"{args.topic} carries {', '.join(others)} on the wire, not "
               f"{FLOAT64_MULTI_ARRAY}" if others else "is arm_sim_node running with the same "
               "ROS_DOMAIN_ID and ROS_AUTOMATIC_DISCOVERY_RANGE?")
        print(f"send-torque: no subscriber on {args.topic} after {args.wait:g} s; {why}",
              file=sys.stderr)
        return 1
    torques = list(args.torques)
    publisher.refusals.first_count(DIAGNOSTICS_WAIT)
    if args.once:
        publisher.send(torques)
        refused = publisher.refusals.after(1, DIAGNOSTICS_WAIT)
    else:
        print(f"sending {torques} N m at {args.rate:g} Hz" +
              (f" for {args.duration:g} s" if args.duration is not None else "; Ctrl-C stops"),
              flush=True)
        refused = publisher.repeat(torques, args.rate, args.duration)
    if refused:
        print(f"arm-sim: error: {refused}", file=sys.stderr)
        return 1
    if args.once:
        print(f"sent {torques} N m once")
    return 0


class Refusals:
    """What the arm_sim nodes on /diagnostics say of the commands they refused: each node's
    refused_commands and received_commands counts when first read (the count before), the
    latest, and why the latest refused command was (last_refusal)."""

    def __init__(self, participant, msg):
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        self.first, self.latest = {}, {}
        self.reader = DataReader(participant, Topic(participant, msg.ros_topic(
            DIAGNOSTICS_TOPIC), msg.DiagnosticArray), qos=msg.default_qos(msg.DiagnosticArray))

    def read(self) -> int:
        """Take what arrived; how many statuses with the counts did."""
        found = 0
        for sample in self.reader.take(N=1000):
            for status in getattr(sample, "status", ()):
                values = {kv.key: kv.value for kv in status.values}
                try:
                    counts = (int(values["refused_commands"]), int(values["received_commands"]))
                except (KeyError, ValueError):
                    continue            # not an arm_sim node's simulation status
                key = (status.hardware_id, status.name)
                self.first.setdefault(key, counts)
                self.latest[key] = (*counts, values.get("last_refusal", "none"),
                                    values.get("policy", "command"))
                found += 1
        return found

    def first_count(self, timeout: float) -> bool:
        """The counts before anything is sent: wait up to `timeout` s for a first status
        (none: a subscriber that is no arm_sim node, whose refusals cannot be read)."""
        deadline = time.monotonic() + timeout
        while not self.first and time.monotonic() < deadline:
            self.read()
            time.sleep(0.02)
        return bool(self.first)

    def refused(self, sent: int) -> str | None:
        """Why, if a node's refused count rose since the first read, or its policy ignores
        torque commands: the line to say."""
        for key, (refused, _, why, policy) in self.latest.items():
            rose = refused - self.first[key][0]
            if rose > 0:
                return (f"the node refused {min(rose, sent)} of the {sent} commands sent: {why} "
                        f"(its /diagnostics refused_commands rose from {self.first[key][0]} "
                        f"to {refused})")
            if policy not in COMMAND_POLICIES:
                return (f"the node's policy {policy!r} ignores torque commands (its "
                        "/diagnostics say so): set its policy to command, e.g. `ros2 param "
                        "set /arm_sim policy command`")
        return None

    def after(self, sent: int, timeout: float) -> str | None:
        """Once all is sent: wait (up to `timeout` s) until every node's status says it has
        received what was sent since the first read, then whether it refused any."""
        deadline = time.monotonic() + timeout
        while self.first and time.monotonic() < deadline:
            self.read()
            if all(received - self.first[key][1] >= sent
                   for key, (_, received, *_) in self.latest.items()) and self.latest:
                break
            time.sleep(0.02)
        return self.refused(sent)


class TorquePublisher:
    """A Float64MultiArray writer on `rt/<topic>` with the ROS default QoS."""

    def __init__(self, topic: str = "joint_torque_commands", domain_id=None, config=None):
        from cyclonedds.builtin import (BuiltinDataReader, BuiltinTopicDcpsPublication,
                                        BuiltinTopicDcpsSubscription)
        from cyclonedds.core import InstanceState, ReadCondition
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic

        from ...node.wire import messages as msg

        self._msg = msg
        self.participant = msg.make_participant(domain_id, config)
        self.topic = msg.ros_topic(topic)
        self.writer = DataWriter(
            self.participant, Topic(self.participant, self.topic, msg.Float64MultiArray),
            qos=msg.default_qos(msg.Float64MultiArray))
        self.refusals = Refusals(self.participant, msg)     # read along with discovery
        # what discovery finds meanwhile, to name a type that stops a match (other_types)
        self._endpoints = [(reader, ReadCondition(reader, InstanceState.Alive)) for reader in (
            BuiltinDataReader(self.participant, kind)
            for kind in (BuiltinTopicDcpsPublication, BuiltinTopicDcpsSubscription))]

    def other_types(self) -> list:
        """The ROS types other endpoints on the wire use on this topic, if not ours (a
        subscriber of another type never matches), as discovery has told the readers made
        with the writer."""
        found = {e.type_name for reader, alive in self._endpoints
                 for e in reader.take(N=10_000, condition=alive) if e.topic_name == self.topic}
        return sorted(ros_type(t) for t in found - {"std_msgs::msg::dds_::Float64MultiArray_"})

    def wait_for_subscriber(self, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while not self._msg.matched(self.writer):
            if time.monotonic() > deadline:
                return False
            time.sleep(0.02)
        return True

    def send(self, torques, acknowledged: bool = True) -> None:
        self.writer.write(self._msg.Float64MultiArray(data=[float(t) for t in torques]))
        if acknowledged:
            self.writer.wait_for_acks(self._seconds(1.0))  # delivered before we exit

    def repeat(self, torques, rate: float, duration: float | None) -> str | None:
        """At `rate` until `duration` s (wall) have passed: each message written on its
        schedule (waiting for acknowledgements at each held the rate near 10 Hz), the last
        acknowledged. Stops early where the node's diagnostics say it refuses them: why."""
        start, sent = time.monotonic(), 0
        try:
            while duration is None or sent / rate < duration:
                self.send(torques, acknowledged=False)
                sent += 1
                if self.refusals.read() and (refused := self.refusals.refused(sent)):
                    return refused
                time.sleep(max(0.0, start + sent / rate - time.monotonic()))
        finally:
            self.writer.wait_for_acks(self._seconds(1.0))   # delivered before we exit
        return self.refusals.after(sent, DIAGNOSTICS_WAIT)

    @staticmethod
    def _seconds(s: float) -> int:
        from cyclonedds.util import duration
        return duration(seconds=s)


def ros_type(dds_type: str) -> str:
    """`sensor_msgs::msg::dds_::JointState_` as ROS names it: sensor_msgs/msg/JointState."""
    return dds_type.replace("::dds_::", "::").removesuffix("_").replace("::", "/")
