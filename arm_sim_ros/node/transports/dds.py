"""The arm_sim node on cyclonedds, as a ROS 2 peer on rmw_cyclonedds sees it.

Mirrors the rclpy transport: a publisher of joint_states and /diagnostics (and, once the
scene has sensors, of ~/true_joint_states, announced then), a subscription to
joint_torque_commands, a tick timer and a 1 Hz diagnostics timer, plus the
`ros_discovery_info` announcement that makes `ros2 node list` show the node, and the
parameter services, `~/reset` and /parameter_events (dds_services.py). Ticks can be driven
from outside (tests, benchmarks) or by `spin()`.
"""
from __future__ import annotations

import logging
import time

from cyclonedds._clayer import ddspy_write
from cyclonedds.core import (DDSException, InstanceState, ReadCondition, SampleState, ViewState,
                             WaitSet)
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from ..wire import messages as msg
from ..wire.cdr import clock_cdr, joint_state_bytes
from ...interface import (COMMAND_TOPIC, DIAGNOSTICS_TOPIC, NODE_NAME, SETPOINT_TOPICS,
                          TRUE_JOINT_STATES_TOPIC, split_stamp)
from ..core import ArmSimCore
from ..diagnostics import DiagnosticData, JointStateData
from ..params.parameters import resolve_parameters
from ..params.ros_args import remap_name
from ..schedule import TickSchedule
from ..services.simulation import SimulationControl
from .dds_graph import NameWatch
from .dds_services import DdsServices

LOCKSTEP_WAIT = 0.01   # wall seconds a lockstep node waits for a command before serving again
SERVE_SLICE = 0.1      # wall seconds the loop sleeps at most before it looks again


def _stamp(stamp_ns: int) -> msg.Time:
    return msg.Time(*split_stamp(stamp_ns))


def write_cdr(writer: DataWriter, data: bytes) -> None:
    """DataWriter.write of a sample serialized already (cdr.py): what cyclonedds-python
    11.0.1's write does once its sample.serialize() has run (pub.py), with no sample built:
    the node writes a JointState and a Clock every tick."""
    result = ddspy_write(writer._ref, data)
    if result < 0:
        raise DDSException(result, f"Occurred while writing sample in {writer!r}")


def to_diagnostic_array(data: DiagnosticData) -> msg.DiagnosticArray:
    status = msg.DiagnosticStatus(level=data.level, name=data.name, message=data.message,
                                  hardware_id=data.hardware_id,
                                  values=[msg.KeyValue(k, v) for k, v in data.values])
    return msg.DiagnosticArray(header=msg.Header(stamp=_stamp(data.stamp_ns)), status=[status])


def clock_listened(core: ArmSimCore, clock_writer) -> bool:
    """Whether a node listens on /clock (a use_sim_time peer), as lockstep asks (core.tick):
    False outside lockstep, asking DDS nothing (a match count is a DDS call every tick)."""
    values = core.config.values
    return values["lockstep"] and values["publish_clock"] and msg.matched(clock_writer) > 0


class DdsArmSimNode:
    def __init__(self, parameters: dict, *, domain_id: int | None = None, config: str | None = None,
                 log=None, wall_clock=time.monotonic, start_stamp_ns: int | None = None,
                 recorder=None, name: str = NODE_NAME, namespace: str = "/",
                 remap: dict | None = None):
        # Validate everything before any DDS entity exists: a refusal leaves nothing behind.
        node_config = resolve_parameters(parameters)
        self.name, self.namespace = name, namespace
        self.log = log or logging.getLogger(name)
        self.wall_clock = wall_clock
        self.participant = msg.make_participant(domain_id, config)
        # Topic and service names as rcl resolves them: expanded, then remapped (-r from:=to).
        self.resolve = lambda ros_name: remap_name(ros_name, name, namespace, remap)  # noqa: E731
        topic = lambda ros_name: msg.ros_topic(self.resolve(ros_name))  # noqa: E731
        values = node_config.values
        self.joint_state_writer = self._writer(topic(values["joint_states_topic"]), msg.JointState)
        self.truth_writer = None        # ~/true_joint_states: made with the first truth
        self._topic = topic
        self.diagnostics_writer = self._writer(topic(DIAGNOSTICS_TOPIC), msg.DiagnosticArray)
        # /clock at the ROS default QoS: it matches rclpy's best-effort subscription too
        self.clock_writer = self._writer(topic("/clock"), msg.Clock)
        self.command_reader = self._reader(topic(COMMAND_TOPIC), msg.Float64MultiArray)
        self.joint_command_reader = self._reader(topic(values["joint_commands_topic"]),
                                                 msg.JointState)
        self.setpoint_readers = {field: self._reader(topic(name), msg.Float64MultiArray)
                                 for field, name in SETPOINT_TOPICS.items()}
        self._command_ready = WaitSet(self.participant)
        for reader in (self.command_reader, self.joint_command_reader,
                       *self.setpoint_readers.values()):
            self._command_ready.attach(ReadCondition(
                reader, SampleState.Any | ViewState.Any | InstanceState.Any))
        # rcl_interfaces parameter services, ~/reset, /parameter_events
        self.services = DdsServices(self.participant, name, namespace, self.log,
                                    resolve=self.resolve)
        self._announce()
        self.name_watch = NameWatch(self.participant, namespace, name, self.log)
        self.core = ArmSimCore(node_config, self.log, wall_clock, start_stamp_ns, recorder)
        self.simulation = SimulationControl(self.core, self._publish, self.take_commands)
        self.services.attach(self.core, self.simulation)
        self._publish_clock()      # use_sim_time nodes (controller_manager) wait for a first one
        self._publish_lockstep()   # in lockstep, the state the first command answers

    def _reader(self, topic_name: str, message_type) -> DataReader:
        return DataReader(self.participant, Topic(self.participant, topic_name, message_type),
                          qos=msg.default_qos(message_type))

    def _writer(self, topic_name: str, message_type) -> DataWriter:
        return DataWriter(self.participant, Topic(self.participant, topic_name, message_type),
                          qos=msg.default_qos(message_type))

    def _announce(self) -> None:
        """Publish ros_discovery_info: the graph entry `ros2 node list` reads (transient-local,
        so tools that start later still see it); again when an endpoint is added."""
        if getattr(self, "discovery_writer", None) is None:
            self.discovery_writer = DataWriter(
                self.participant,
                Topic(self.participant, "ros_discovery_info", msg.ParticipantEntitiesInfo),
                qos=msg.discovery_info_qos())
        truth = [msg.gid(self.truth_writer)] if self.truth_writer is not None else []
        node = msg.NodeEntitiesInfo(
            node_namespace=self.namespace, node_name=self.name,
            reader_gid_seq=[msg.gid(self.command_reader), msg.gid(self.joint_command_reader)]
            + [msg.gid(r) for r in self.setpoint_readers.values()]
            + [msg.gid(r) for r in self.services.readers],   # service requests
            writer_gid_seq=[msg.gid(self.joint_state_writer), msg.gid(self.diagnostics_writer),
                            msg.gid(self.clock_writer)] + truth
            + [msg.gid(w) for w in self.services.writers])   # replies, parameter events
        self.discovery_writer.write(msg.ParticipantEntitiesInfo(
            gid=msg.gid(self.participant), node_entities_info_seq=[node]))

    # callbacks, as the rclpy node has them ------------------------------------------------

    def take_commands(self, timeout: float = 0.0) -> int:
        """Hand every waiting command to the core, waiting up to `timeout` s for the first.
        Returns how many arrived (refused ones included)."""
        # one look at the read conditions, instead of a take on every reader each tick
        if not self._command_ready.wait(duration(seconds=timeout) if timeout > 0 else 0):
            return self._publish_lockstep()
        count = 0
        for sample in self.command_reader.take(N=256):
            if isinstance(sample, msg.Float64MultiArray):  # InvalidSample: lifecycle, no data
                self.core.on_command(sample.data)
                count += 1
        for field, reader in self.setpoint_readers.items():
            for sample in reader.take(N=256):
                if isinstance(sample, msg.Float64MultiArray):
                    self.core.on_setpoint_command(field, sample.data)
                    count += 1
        for sample in self.joint_command_reader.take(N=256):
            if isinstance(sample, msg.JointState):
                stamp = sample.header.stamp
                self.core.on_joint_state_command(sample.name, sample.position, sample.velocity,
                                                 sample.effort, stamp.sec * 10**9 + stamp.nanosec)
                count += 1
        return self._publish_lockstep(count)

    def _publish_lockstep(self, count: int = 0) -> int:
        for data in self.core.lockstep.take():   # lockstep: a tick per answer
            self._publish(data)
        return count

    def tick(self, wall_now: float | None = None) -> JointStateData | None:
        """The timer callback: take commands, step, publish joint_states (and /clock); in
        lockstep the commands tick instead and the timer only serves."""
        self.take_commands()
        self.services.poll()   # answer service requests between ticks
        data = self.core.tick(wall_now, clock_listened(self.core, self.clock_writer))
        if data is not None:
            self._publish(data)
        return data

    def _publish(self, data: JointStateData) -> None:
        """joint_states and /clock, serialized straight from the data (cdr.py: the bytes a
        messages.JointState and messages.Clock serialize to, with neither built)."""
        self._publish_states(data)
        if self.core.config.values["publish_clock"]:     # after the state: its time
            write_cdr(self.clock_writer, clock_cdr(*split_stamp(data.stamp_ns)))

    def _publish_states(self, data: JointStateData) -> None:
        """joint_states; with sensors, the readings there and the state on
        ~/true_joint_states at the same stamp."""
        sec, nanosec = split_stamp(data.stamp_ns)
        write_cdr(self.joint_state_writer, joint_state_bytes(
            sec, nanosec, data.frame_id, data.name, data.position, data.velocity, data.effort))
        if (truth := data.truth) is not None:
            if self.truth_writer is None:
                self.truth_writer = self._writer(self._topic(TRUE_JOINT_STATES_TOPIC),
                                                 msg.JointState)
                self._announce()
            write_cdr(self.truth_writer, joint_state_bytes(
                sec, nanosec, truth.frame_id, truth.name, truth.position, truth.velocity,
                truth.effort))

    def _publish_clock(self) -> None:
        """The current time on /clock: at start, and while lockstep waits for a command."""
        if self.core.config.values["publish_clock"]:
            self.clock_writer.write(msg.Clock(_stamp(self.core.stamp_ns())))

    def publish_diagnostics(self, wall_now: float | None = None) -> DiagnosticData:
        data = self.core.diagnostics(wall_now)
        self.diagnostics_writer.write(to_diagnostic_array(data))
        return data

    # the loop ------------------------------------------------------------------------------

    def spin(self, duration_s: float | None = None, on_status=None, stopped=None) -> None:
        """Tick at publish_rate x real_time_factor (as fast as possible when 0) until the
        simulated time since start reaches `duration_s`, or forever: whatever publish_rate,
        step_size or lockstep become meanwhile, and across resets. Once a wall second:
        diagnostics and `on_status(line)`. Late ticks are made up as schedule.py says. Every
        tick is exactly steps_per_tick steps. `stopped()` true: KeyboardInterrupt (a signal
        whose own was dropped, main.Stop)."""
        end_ns = None if duration_s is None else round(duration_s * 1e9)
        schedule = TickSchedule(self.wall_clock())
        next_status = schedule.next_tick + 1.0
        while end_ns is None or self.core.stamp_ns() - self.core.start_stamp_ns < end_ns:
            if stopped is not None and stopped():
                raise KeyboardInterrupt
            now = self.wall_clock()
            if self.core.config.values["lockstep"]:
                self.services.poll()                   # answers tick: wait for them
                if not self.take_commands(timeout=LOCKSTEP_WAIT):
                    lockstep_idle(self, now)
            elif schedule.wait(now) > 0:
                # sleep, serving, in slices: a signal is handled and a new period (a
                # parameter set) is taken up within SERVE_SLICE
                period = self.core.config.wall_period
                self.services.serve_for(min(schedule.wait(now), SERVE_SLICE))
                now = self.wall_clock()
                if self.core.config.wall_period < period:
                    schedule.next_tick = min(schedule.next_tick, now + self.core.config.wall_period)
            else:
                self.tick(now)
                # the period now: a parameter set may have changed it
                schedule.ticked(now, self.core.config.wall_period)
            if now >= next_status:
                self._status(now, on_status)
                next_status = now + 1.0
        self._status(self.wall_clock(), None)     # the last diagnostics; the stop line says the rest

    def _status(self, now: float, on_status) -> None:
        self.name_watch.check()
        rtf = self.core.real_time_factor(now)
        self.publish_diagnostics(now)
        if on_status is not None:
            on_status(self.core.status_line(rtf))

    def close(self) -> None:
        """Finish telemetry and leave the DDS graph (cyclonedds deletes an entity when its
        last Python reference goes)."""
        self.core.finish()
        self.services.close()
        self._command_ready = self.command_reader = self.discovery_writer = None
        self.joint_command_reader = self.clock_writer = self.name_watch = None
        self.setpoint_readers = {}
        self.joint_state_writer = self.diagnostics_writer = self.participant = None
        self.truth_writer = None


def lockstep_idle(node: DdsArmSimNode, now: float) -> None:
    """No answer came for LOCKSTEP_WAIT: the time on /clock (a use_sim_time peer may wait
    for it), or lockstep_wait's tick of its own; the state awaiting its answer again where
    it may not have reached a controller (schedule.Lockstep.resend); and what the recorder
    keeps, to its file."""
    core = node.core
    data = core.tick(now, clock_listened(core, node.clock_writer))
    if data is None:
        node._publish_clock()
    else:
        node._publish(data)
    if data is None and core.lockstep.resend(msg.matched(node.joint_state_writer), now):
        node._publish_states(core.joint_state())
    core.recorder.idle()
