"""`arm-sim record [--topics NAME:TYPE ...] DIR`: a rosbag2 recorder for machines without ROS.

It joins the ROS 2 wire through the dds transport (the same discovery settings as
rmw_cyclonedds, from ROS_DOMAIN_ID, ROS_AUTOMATIC_DISCOVERY_RANGE, ROS_STATIC_PEERS and
CYCLONEDDS_URI), subscribes to the node's topics and any other JointState or
Float64MultiArray topic named, and writes what arrives as `ros2 bag record` would, except
that bag time is when the publisher sent each message (its DDS source timestamp) rather
than when it arrived: on one machine the two differ by the ~0.3 ms transport latency, and
the send time keeps the publishing cadence that `ros2 bag play` reproduces. Messages keep
their own header stamps; each topic carries the QoS its publishers offered, as discovery
reports it. The recording stops at Ctrl-C, SIGTERM, SIGHUP or --duration (counted from
the first message: a recorder started before its node waits --wait for it) within about
two seconds even under a flood (a second signal stops at once), drains the readers and
closes the bag, so every message received is kept. Each reader is reliable and keeps the last
READER_DEPTH samples not yet written (as `ros2 bag record` keeps a keep-last queue): memory
stays bounded, and a publisher that outpaces the disk for longer loses its oldest
unwritten samples rather than delaying a stop. Every REPORT_SECONDS a line on stderr gives
the count per topic, or says that no publisher has been seen yet. A recording that received
nothing leaves no bag and exits 1.

The bag opens at every moment (recording.bag): a kill -9 loses at most the last
CHUNK_SECONDS of messages; a full disk or file-size limit closes it with what fit.
"""
from __future__ import annotations

import time

from ...interface import KNOWN_TOPICS, SENSOR_TOPICS, wrong_type
from ...usage import UsageError
from ..signals import StopOnSignals

DEFAULT_TOPICS = {"/joint_states": "sensor_msgs/msg/JointState",
                  "/joint_torque_commands": "std_msgs/msg/Float64MultiArray",
                  "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
                  **SENSOR_TOPICS}     # the truth beside readings: in the bag once it comes
EXTRA_TYPES = ("sensor_msgs/msg/JointState", "std_msgs/msg/Float64MultiArray")
POLL_SECONDS = 0.1  # how soon a stop request is noticed
TAKE_BATCH = 256
READER_DEPTH = 1000  # samples a reader keeps before it drops its oldest (keep-last)
QUIET_SECONDS = 0.1  # after a stop: no data for this long means everything sent has arrived
FLUSH_SECONDS = 1.5  # ... and this bounds the wait when publishers keep going
REPORT_SECONDS = 3.0
WAIT = 30.0        # with --duration: how long to wait for a first message (send-torque's too)


def parse_topic(text: str) -> tuple[str, str]:
    """`name:type`, type as `sensor_msgs/msg/JointState` or just `JointState`."""

    from ...node.wire.messages import check_topic_name

    name, sep, short = text.rpartition(":")
    matches = [t for t in EXTRA_TYPES if short in (t, t.rsplit("/", 1)[-1])]
    if not sep or not name.strip("/") or not matches:
        raise UsageError(f"--topics {text!r} must be NAME:TYPE with TYPE one of "
                         f"{', '.join(EXTRA_TYPES)} (or its last part, e.g. JointState)")
    name = check_topic_name("/" + name.removeprefix("/"), f"--topics {text!r}: the name")
    if problem := wrong_type(name, matches[0]):
        fix = ("it is recorded by default" if name in DEFAULT_TOPICS else
               f"--topics {name}:{KNOWN_TOPICS[name].rsplit('/', 1)[-1]}")
        raise UsageError(f"--topics {text!r}: {problem} (the arm_sim node's topic); {fix}")
    return name, matches[0]


class TopicRecorder:
    """Readers for `topics` on `participant`, writing each sample into a BagWriter.

    A topic enters the bag with its first message, when its publishers have certainly
    been discovered, so the offered QoS written is theirs.
    """

    def __init__(self, participant, topics: dict[str, str], writer=None):
        from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
        from cyclonedds.core import ReadCondition, SampleState, ViewState, InstanceState, WaitSet
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        from ...node.wire import messages as wire

        self.writer = writer
        self.topics = topics
        self._offers: dict[str, dict] = {}   # DDS topic -> {publication key: Qos}
        self._publications = BuiltinDataReader(participant, BuiltinTopicDcpsPublication)
        self._waitset = WaitSet(participant)
        self._readers = {}
        wire_types = {ros: cls for cls, ros in wire.ROS_TYPE_NAMES.items()}
        any_sample = SampleState.Any | ViewState.Any | InstanceState.Any
        for name, msgtype in topics.items():
            cls = wire_types[msgtype]
            # Reliable, keep-last READER_DEPTH: bounded memory, and no backlog to wait for at a
            # stop (keep-all held 1.2M samples under a flood; reader-side limits that hold the
            # publisher back make deleting the reader wait ~10 s).
            qos = wire.default_qos(cls, depth=READER_DEPTH)
            reader = DataReader(participant, Topic(participant, wire.ros_topic(name), cls), qos=qos)
            self._waitset.attach(ReadCondition(reader, any_sample))
            self._readers[name] = reader
        self._matched = wire.matched

    def poll(self, timeout: float = POLL_SECONDS, stop=None, until: float | None = None,
             after: int | None = None) -> int:
        """Wait up to `timeout` s for data, then write what is available (see drain);
        returns the send time (ns) of the newest sample written, 0 if none."""
        self._waitset.wait(int(timeout * 1e9))
        return self.drain(stop, time.monotonic() + POLL_SECONDS if until is None else until,
                          after)

    def drain(self, stop=None, until: float | None = None, after: int | None = None) -> int:
        """Write the samples the readers hold, TAKE_BATCH at a time from each in turn, until
        they are empty, `stop.requested` or the monotonic time `until`; a reader that gave a
        sample sent after `after` (ns) has given all sent before. Returns the newest send
        time written (0 if none)."""
        from cyclonedds.internal import InvalidSample

        newest, more, passed = 0, True, set()
        while more and not (stop is not None and stop.requested) and \
                (until is None or time.monotonic() < until):
            more = False
            for name, reader in self._readers.items():
                if name in passed:
                    continue
                taken = reader.take(N=TAKE_BATCH)
                more |= len(taken) == TAKE_BATCH
                samples = [s for s in taken if not isinstance(s, InvalidSample)]
                if samples and name not in self.writer:
                    self._add(name)
                for sample in samples:
                    sent = sample.sample_info.source_timestamp
                    self.writer.write(name, sent, self._message(name, sample))
                    newest = max(newest, sent)
                    if after is not None and sent > after:
                        passed.add(name)
        return newest

    def run(self, stop, duration: float | None = None, report=None,
            wait: float = WAIT) -> None:
        """Record until `stop.requested` or `duration` wall seconds after the first message
        (a recorder started before its node waits for it, with a duration at most `wait`
        seconds), then flush; `report` (a function taking a line) hears the counts every
        REPORT_SECONDS."""
        started = time.monotonic()
        end = None
        next_report = started + REPORT_SECONDS
        while not stop.requested and (end is None or time.monotonic() < end):
            if end is None and duration is not None and time.monotonic() - started > wait:
                break                     # nothing came: the caller says so
            self.poll(POLL_SECONDS if end is None
                      else min(POLL_SECONDS, max(0.0, end - time.monotonic())), stop)
            self.writer.checkpoint()
            if end is None and duration is not None and any(self.writer.counts.values()):
                end = time.monotonic() + duration
            if report is not None and time.monotonic() >= next_report:
                report(self.progress(time.monotonic() - started))
                next_report += REPORT_SECONDS
        self.flush(time.time_ns())

    def progress(self, seconds: float) -> str:
        """`record: 6 s: /joint_states 600, /diagnostics no publisher yet`."""
        parts, seen = [], False
        for name, reader in self._readers.items():
            count = self.writer.counts.get(name, 0)
            publishers = self._matched(reader)
            seen |= bool(publishers or count)
            parts.append(f"{name} {count}" if publishers or count else f"{name} no publisher yet")
        hint = "" if seen else ("; is the node running, with the same ROS_DOMAIN_ID and "
                                "ROS_AUTOMATIC_DISCOVERY_RANGE?")
        return f"record: {seconds:.0f} s: {', '.join(parts)}{hint}"

    def flush(self, stopped_ns: int) -> None:
        """Write what was sent before the stop. DDS acknowledges a sample before its reader
        can take it (it may sit in a delivery queue), so keep taking until a quiet interval,
        a sample sent after the stop (in-order delivery: the rest has arrived), or
        FLUSH_SECONDS; the readers hold at most READER_DEPTH samples each, so a flood ends
        as quickly."""
        deadline = time.monotonic() + FLUSH_SECONDS
        while time.monotonic() < deadline:
            newest = self.poll(QUIET_SECONDS, until=deadline, after=stopped_ns)
            if newest == 0 or newest > stopped_ns:
                return

    def _message(self, name, sample):
        from ...recording.bags.bag import message_from

        return message_from(self.topics[name], sample)

    def _add(self, name: str) -> None:
        from ...recording.bags.bag import NODE_QOS
        from ...node.wire.messages import ros_topic

        for endpoint in self._publications.take(N=10_000):
            self._offers.setdefault(endpoint.topic_name, {})[endpoint.key] = endpoint.qos
        offers = [offer_from_dds(q) for q in self._offers.get(ros_topic(name), {}).values()]
        self.writer.add_topic(name, self.topics[name], offers or [NODE_QOS])


def offer_from_dds(qos):
    """A discovered writer's DDS QoS as the ROS graph (and so rosbag2) reports it."""
    from cyclonedds.core import dds_infinity
    from cyclonedds.qos import Policy

    from ...recording.bags.bag import INFINITE, QosLiveliness, QosTime, offered_qos

    def duration(policy, attribute):  # an absent policy means infinite, as in DDS
        ns = dds_infinity if policy is None else getattr(policy, attribute)
        return INFINITE if ns >= dds_infinity else QosTime(ns // 10**9, ns % 10**9)

    liveliness = qos[Policy.Liveliness]
    manual = isinstance(liveliness, Policy.Liveliness.ManualByTopic)
    return offered_qos(
        "best_effort" if qos[Policy.Reliability] == Policy.Reliability.BestEffort else "reliable",
        "transient_local" if qos[Policy.Durability] == Policy.Durability.TransientLocal
        else "volatile",
        deadline=duration(qos[Policy.Deadline], "deadline"),
        lifespan=duration(qos[Policy.Lifespan], "lifespan"),
        liveliness=QosLiveliness.MANUAL_BY_TOPIC if manual else QosLiveliness.AUTOMATIC,
        lease=duration(liveliness, "lease_duration"))


def record(path, topics: dict[str, str], participant, duration: float | None = None,
           stop=None, report=None, wait: float = WAIT) -> dict[str, int]:
    """Record until `stop.requested` or `duration` wall seconds after the first message;
    returns messages per topic.
    The readers come first: a topic DDS refuses leaves no bag behind."""
    from ...recording.bags.bag import BagWriter

    recorder = TopicRecorder(participant, topics)
    with BagWriter(path, start_ns=time.time_ns()) as writer:
        recorder.writer = writer
        recorder.run(stop or StopOnSignals(), duration, report, wait)
        return dict(writer.counts)


def cmd_record(args) -> int:
    import sys
    from pathlib import Path

    from math import isfinite

    from ...node.wire.one_cyclone import require_cyclonedds

    require_cyclonedds("arm-sim record")
    from ...recording.bags.bag import BagError
    from ...node.wire.messages import make_participant
    from ...outputs import clear_output

    topics = dict(DEFAULT_TOPICS)
    topics.update(parse_topic(t) for text in args.topics or [] for t in text.split(",") if t)
    for name, value in (("--duration", args.duration), ("--wait", args.wait)):
        if value is not None and not (isfinite(value) and value > 0):
            raise BagError(f"{name} {value} must be a positive number of seconds")
    if Path(args.dir).exists():  # refused before joining the network
        raise BagError(f"{args.dir} exists already; a recording never overwrites one")
    participant = make_participant()   # a bad environment: DiscoveryError, one line

    def report(line):
        print(line, file=sys.stderr, flush=True)

    # SIGINT, SIGTERM or SIGHUP: the loop stops, drains and closes the bag; a second signal
    # raises KeyboardInterrupt, and the bag is still closed.
    with StopOnSignals() as stop:
        report(f"recording {', '.join(topics)} into {args.dir} (Ctrl-C to stop)")
        counts = record(args.dir, topics, participant, args.duration, stop, report, args.wait)
    if not any(counts.values()):     # an empty bag would only block the next try's name
        clear_output(args.dir)
        print(f"record: no message arrived on {', '.join(topics)}; no bag written. Is the "
              "node running (and publishing while this records), with the same ROS_DOMAIN_ID "
              "and ROS_AUTOMATIC_DISCOVERY_RANGE?", file=sys.stderr, flush=True)
        return 1
    summary = ", ".join(f"{topic} {n}" for topic, n in counts.items())
    print(f"wrote {args.dir}: {summary}", flush=True)
    return 0


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "record", help="record the arm's topics from the ROS 2 wire into a rosbag2 (MCAP)")
    parser.add_argument("dir", metavar="DIR", help="bag directory to create (must not exist)")
    parser.add_argument("--topics", action="append", metavar="NAME:TYPE[,NAME:TYPE...]",
                        help="more topics to record (repeatable, or comma-separated), e.g. "
                             "/target:JointState,/effort:std_msgs/msg/Float64MultiArray")
    parser.add_argument("--duration", type=float,
                        help="stop this many seconds after the first message (a node may "
                             "start after the recorder)")
    parser.add_argument("--wait", type=float, default=WAIT,
                        help=f"with --duration: seconds to wait for a first message "
                             f"(default {WAIT:g}); then it stops, having recorded nothing")
    parser.set_defaults(func=cmd_record)
