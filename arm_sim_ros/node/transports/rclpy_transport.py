"""The arm_sim node on rclpy (ROS 2 Jazzy), written as the ros2/examples nodes are.

Parameters are declared from the node core's single list, with the scene's values as
defaults; a set-parameters callback hands changes to the core, which refuses bad ones with a
reason. `~/reset` (std_srvs/srv/Trigger) restarts the scene.
"""
from __future__ import annotations

import time

import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

from ...interface import (COMMAND_TOPIC, DIAGNOSTICS_TOPIC, NODE_NAME, SETPOINT_TOPICS,
                          TRUE_JOINT_STATES_TOPIC, split_stamp)
from ..core import ArmSimCore
from ..diagnostics import DiagnosticData, JointStateData
from ..services.parameter_services import could_not_apply
from ..params.parameters import (PARAMETERS, READ_ONLY, SPECS, resolve_parameters,
                                 scene_defaults)
from ..params.values import ParameterRefused
from ..schedule import TickSchedule
from ..services.simulation import SimulationControl
from ..wire.cdr import clock_cdr, joint_state_bytes
from . import rclpy_simulation


def _stamp(stamp_ns: int) -> Time:
    sec, nanosec = split_stamp(stamp_ns)
    return Time(sec=sec, nanosec=nanosec)


def to_joint_state(data: JointStateData, message: JointState | None = None) -> JointState:
    """`data` as a JointState: into `message` when given (a publisher's own, reused every
    tick: publish serializes it at once, and a message built anew costs more than the
    publish)."""
    message = JointState() if message is None else message
    message.header.stamp.sec, message.header.stamp.nanosec = split_stamp(data.stamp_ns)
    message.header.frame_id = data.frame_id
    message.name = data.name
    message.position = data.position
    message.velocity = data.velocity
    message.effort = data.effort
    return message


# What rmw_writes_our_cdr asks the RMW to serialize: odd-length strings, every sequence.
SAMPLE = JointStateData(3 * 10**9 + 7, "f", ["j1", "joint_2"], [0.5, -1.0], [2.0, 0.25],
                        [-3.5, 1e-3])


def rmw_writes_our_cdr() -> bool:
    """Whether this RMW serializes a JointState and a Clock to the bytes cdr.py writes (XCDR1,
    as rmw_cyclonedds does): then they are published as those bytes (Publisher.publish of
    a serialized message), a fifth of the cost of a message converted for the RMW each tick.
    Asked of the RMW itself at start (rclpy's serialize_message), so another RMW that
    serializes otherwise gets messages, and the wire is the RMW's own either way."""
    sec, nanosec = split_stamp(SAMPLE.stamp_ns)
    clock = Clock(clock=_stamp(SAMPLE.stamp_ns))
    return (serialize_message(to_joint_state(SAMPLE)) == joint_state_bytes(sec, nanosec,
                                                                            *SAMPLE[1:6])
            and serialize_message(clock) == clock_cdr(sec, nanosec))


def to_diagnostic_array(data: DiagnosticData) -> DiagnosticArray:
    status = DiagnosticStatus(level=bytes([data.level]), name=data.name, message=data.message,
                              hardware_id=data.hardware_id,
                              values=[KeyValue(key=k, value=v) for k, v in data.values])
    message = DiagnosticArray(status=[status])
    message.header.stamp = _stamp(data.stamp_ns)
    return message


class ArmSimNode(Node):
    def __init__(self, wall_clock=time.monotonic, recorder=None, status=None, **node_kwargs):
        super().__init__(NODE_NAME, **node_kwargs)
        self._status = status
        # The scene and the URDF first (read-only): every other default derives from them.
        defaults = scene_defaults(*(self.declare_parameter(
            name, SPECS[name].default,
            ParameterDescriptor(description=SPECS[name].description, read_only=True)).value
            for name in READ_ONLY))
        for spec in PARAMETERS:
            if spec.name not in READ_ONLY:
                # dynamic typing: `-p publish_rate:=100` (an integer) is still a rate; an
                # effect's key the scene does not name is declared without a value (NOT_SET).
                self.declare_parameter(spec.name, defaults[spec.name], ParameterDescriptor(
                    description=spec.description, dynamic_typing=True))
        config = resolve_parameters({name: self.get_parameter(name).value for name in SPECS})
        origin = (self.get_clock().now().nanoseconds   # with use_sim_time: /clock's time
                  if config.values["clock_origin"] == "wall" else 0)
        self.core = ArmSimCore(config, self.get_logger(), wall_clock, origin, recorder)
        self.add_on_set_parameters_callback(self.on_set_parameters)

        values = config.values
        self.joint_state_publisher = self.create_publisher(
            JointState, values["joint_states_topic"], 10)
        self.truth_publisher = None      # ~/true_joint_states, made with the first truth
        self.clock_publisher = self.create_publisher(Clock, "/clock", 10)
        self.serialized, self._strings = rmw_writes_our_cdr(), (None, None, False)
        # else these, filled anew every tick (not `_clock`: rclpy's Node has its own)
        self.joint_state_message, self.clock_message = JointState(), Clock()
        self.diagnostics_publisher = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, 10)
        # Commands and the tick timer in a group of their own: a step_simulation or
        # simulate_steps coroutine holds the default group until it ends, and in lockstep
        # each of its ticks waits for the command that answers the state before it (and the
        # timer sends that state again where it may not have reached the controller).
        self.loop_group = commands = MutuallyExclusiveCallbackGroup()
        self.command_subscription = self.create_subscription(
            Float64MultiArray, COMMAND_TOPIC, self.on_command, 10, callback_group=commands)
        self.joint_command_subscription = self.create_subscription(
            JointState, values["joint_commands_topic"], self.on_joint_command, 10,
            callback_group=commands)
        self.setpoint_subscriptions = [
            self.create_subscription(Float64MultiArray, name,
                                     lambda message, field=field: self.on_setpoint(field, message),
                                     10, callback_group=commands)
            for field, name in SETPOINT_TOPICS.items()]
        self.reset_service = self.create_service(Trigger, "~/reset", self.on_reset)
        self.simulation = SimulationControl(self.core, self._publish)
        self.simulation_services = rclpy_simulation.serve(self, self.simulation)
        self.schedule = TickSchedule(self.core.wall_clock())
        self.tick_timer = self.create_timer(config.wall_period, self.on_timer,
                                            callback_group=self.loop_group)
        self.diagnostics_timer = self.create_timer(1.0, self.on_diagnostics)
        self._publish_clock()           # use_sim_time nodes (controller_manager) wait for one
        self._publish_lockstep()        # in lockstep, the state the first command answers

    def on_command(self, message: Float64MultiArray) -> None:
        self.core.on_command(list(message.data))
        self._publish_lockstep()

    def on_setpoint(self, field: str, message: Float64MultiArray) -> None:
        self.core.on_setpoint_command(field, list(message.data))
        self._publish_lockstep()

    def on_joint_command(self, message: JointState) -> None:
        stamp = message.header.stamp
        self.core.on_joint_state_command(list(message.name), list(message.position),
                                         list(message.velocity), list(message.effort),
                                         stamp.sec * 10**9 + stamp.nanosec)
        self._publish_lockstep()

    def _publish_lockstep(self) -> None:
        for data in self.core.lockstep.take():   # lockstep: a tick per answer
            self._publish(data)

    def on_timer(self) -> None:
        """The tick timer: every tick due by the schedule (TickSchedule.run_due: a late
        callback, as each spin costs Python time, still keeps real_time_factor). In
        lockstep, where the answers tick: the time on /clock (or lockstep_wait's tick), and
        the state awaiting its answer again where it may not have reached a controller
        (schedule.Lockstep.resend)."""
        if self.core.config.values["lockstep"]:
            self._publish_lockstep()      # a play or a reset made one
            idle = self.on_tick() is None
            if idle:
                self._publish_clock()     # the time while lockstep waits (use_sim_time peers)
            if idle and self.core.lockstep.resend(
                    self.joint_state_publisher.get_subscription_count(), self.core.wall_clock()):
                self._publish_states(self.core.joint_state())
            if idle:
                self.core.recorder.idle()
        self.schedule.run_due(self.core, self.on_tick)

    def on_tick(self) -> JointStateData | None:
        values = self.core.config.values    # whether /clock is listened to: lockstep asks it
        data = self.core.tick(clock_listened=values["lockstep"] and values["publish_clock"]
                              and self.clock_publisher.get_subscription_count() > 0)
        if data is not None:
            self._publish(data)
        return data

    def _publish(self, data: JointStateData) -> None:
        """joint_states (_publish_states), then /clock."""
        self._publish_states(data)
        if self.core.config.values["publish_clock"]:
            if self.serialized:
                self.clock_publisher.publish(clock_cdr(*split_stamp(data.stamp_ns)))
            else:
                self.clock_message.clock = _stamp(data.stamp_ns)
                self.clock_publisher.publish(self.clock_message)

    def _publish_states(self, data: JointStateData) -> None:
        """joint_states; with sensors, the readings there and the state on
        ~/true_joint_states at the same stamp."""
        self._publish_state(self.joint_state_publisher, data, self.joint_state_message)
        if data.truth is not None:
            if self.truth_publisher is None:
                self.truth_publisher = self.create_publisher(
                    JointState, TRUE_JOINT_STATES_TOPIC, 10)
                self.truth_message = JointState()
            self._publish_state(self.truth_publisher, data.truth, self.truth_message)

    def _publish_state(self, publisher, data: JointStateData, message: JointState) -> None:
        """`data` as the RMW's own bytes (cdr.py) where it writes them, else in `message`."""
        if self.serialized and self._c_strings(data):
            sec, nanosec = split_stamp(data.stamp_ns)
            publisher.publish(joint_state_bytes(sec, nanosec, data.frame_id, data.name,
                                                data.position, data.velocity, data.effort))
        else:
            publisher.publish(to_joint_state(data, message))

    def _c_strings(self, data: JointStateData) -> bool:
        """No NUL in frame_id or the names: the RMW ends a string at its first NUL, cdr.py
        writes it whole. Asked again only when they are other objects (a parameter set)."""
        if data.frame_id is not self._strings[0] or data.name is not self._strings[1]:
            self._strings = (data.frame_id, data.name, all(
                "\0" not in text for text in (data.frame_id, *data.name)))
        return self._strings[2]

    def _publish_clock(self) -> None:
        if self.core.config.values["publish_clock"]:
            self.clock_publisher.publish(Clock(clock=_stamp(self.core.stamp_ns())))

    def on_diagnostics(self) -> DiagnosticData:
        rtf = self.core.real_time_factor(self.core.wall_clock())
        data = self.core.diagnostics()
        self.diagnostics_publisher.publish(to_diagnostic_array(data))
        if self._status is not None:
            self._status(self.core.status_line(rtf))
        return data

    def on_reset(self, request, response):
        self.core.reset()
        response.success = True
        response.message = f"scene {self.core.config.scene.name} restarted from its initial state"
        return response

    def on_set_parameters(self, parameters) -> SetParametersResult:
        changes = {p.name: p.value for p in parameters}
        try:
            changed = self.core.set_parameters(changes)
        except ParameterRefused as refusal:
            self.get_logger().warning(str(refusal))
            return SetParametersResult(successful=False, reason=str(refusal))
        except Exception as error:   # noqa: BLE001 - raised through rclpy's spin, it ended the node
            self.get_logger().error(f"set_parameters {list(changes)}: "
                                    f"{type(error).__name__}: {error}")
            return SetParametersResult(successful=False, reason=could_not_apply(changes, error))
        if {"publish_rate", "real_time_factor"} & set(changed):      # the wall period
            self.destroy_timer(self.tick_timer)
            self.tick_timer = self.create_timer(self.core.config.wall_period, self.on_timer,
                                                callback_group=self.loop_group)
        return SetParametersResult(successful=True)

    def destroy_node(self):
        self.core.finish()
        return super().destroy_node()


def run(ros_args: list, duration: float | None, status) -> int:
    """Init, spin until the simulated time since start reaches `duration` s (or Ctrl-C),
    whatever publish_rate, step_size or lockstep become meanwhile; shut down."""
    rclpy.init(args=ros_args)
    node = None
    try:
        node = ArmSimNode(status=status)
        end_ns = None if duration is None else round(duration * 1e9)   # simulated time
        while rclpy.ok() and (end_ns is None or
                              node.core.stamp_ns() - node.core.start_stamp_ns < end_ns):
            rclpy.spin_once(node, timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
