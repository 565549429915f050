"""`arm_sim_controllers`: the arm_sim node's companion under ros2_control (rclpy, with
controller_manager_msgs): `follow` keeps the node's servo.interface on what the active
controllers claim; `wait` holds the controllers back until the hardware has read the node.

    arm_sim_controllers follow [--node /arm_sim] [--controller-manager /controller_manager]
    arm_sim_controllers wait [--topic /broadcaster/joint_states] [--timeout 60]

follow: at each controller switch (controller_manager's ~/activity), the command interfaces
the active controllers claim set the node's servo.interface (claims.py), so each joint takes
what its active controller sends: position JTC -> effort JTC -> velocity forward controller,
in any order, with no parameter set by hand. A scene without servos has only effort joints:
nothing to follow, said once.

wait: exits 0 once the joint_state_broadcaster publishes a finite position for every joint,
that is once the hardware has read the node's first JointState; the launch activates the
controllers then, on either transport and clock (exit 1 after --timeout wall seconds).
"""
from __future__ import annotations

import argparse
import sys
import time

from ...usage import DONE, REFUSED, ArgumentParser, UsageError, one_line
from .claims import claimed_interfaces, interfaces_for, started_from, unknown_active

SERVO_INTERFACE = "servo.interface"


def follower_class():
    """The rclpy node class (rclpy and controller_manager_msgs imported here, when run)."""
    from controller_manager_msgs.msg import ControllerManagerActivity
    from controller_manager_msgs.srv import ListControllers
    from rcl_interfaces.msg import ParameterEvent, ParameterType
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    class ControllerFollower(Node):
        """controller_manager's switches into the node's servo.interface."""

        def __init__(self, target: str, manager: str, **node_kwargs):
            super().__init__("arm_sim_controllers", **node_kwargs)
            self.target = target
            self.controllers, self.states = {}, {}     # name -> command interfaces, state
            self.joint_names = self.current = None     # the node's, once it answers
            self.busy = False                          # a request in flight
            self.parameters = AsyncParameterClient(self, target)
            self.list_controllers = self.create_client(ListControllers,
                                                       f"{manager}/list_controllers")
            latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                 durability=DurabilityPolicy.TRANSIENT_LOCAL)
            self.create_subscription(ControllerManagerActivity, f"{manager}/activity",
                                     self.on_activity, latched)
            self.create_subscription(ParameterEvent, "/parameter_events", self.on_event, 10)
            self.create_timer(0.2, self.on_timer)   # what has not answered yet, again

        def on_timer(self) -> None:
            if self.joint_names is None:
                self.ask_node()
            else:
                self.follow()

        def ask_node(self) -> None:
            """The node's joints and interfaces, once its parameter services answer."""
            if self.busy or not self.parameters.services_are_ready():
                return
            self.busy = True
            self.parameters.get_parameters(["joint_names", SERVO_INTERFACE]).add_done_callback(
                self.on_node)

        def on_node(self, future) -> None:
            self.busy = False
            values = future.result().values
            self.joint_names = list(values[0].string_array_value)
            if values[1].type != ParameterType.PARAMETER_STRING_ARRAY:
                self.get_logger().info(f"{self.target} has no servos (its scene names none): "
                                       "its joints take effort only; nothing to follow")
                return
            self.current = list(values[1].string_array_value)
            self.get_logger().info(f"following controller_manager's switches into "
                                   f"{self.target} {SERVO_INTERFACE} (now {self.current})")
            self.follow()

        def on_event(self, event) -> None:
            """servo.interface set by anyone (this node too): the value the node has now."""
            if event.node == self.target:
                for parameter in event.changed_parameters:
                    if parameter.name == SERVO_INTERFACE:
                        self.current = list(parameter.value.string_array_value)

        def on_activity(self, activity) -> None:
            self.states = {c.name: c.state.label for c in activity.controllers}
            self.follow()

        def follow(self) -> None:
            """Ask controller_manager what a controller claims the first time it is active
            (cached: its command interfaces are fixed once configured), then set what the
            active ones claim."""
            if self.busy or self.current is None:
                return
            if unknown_active(self.controllers, self.states):
                if self.list_controllers.service_is_ready():
                    self.busy = True
                    self.list_controllers.call_async(ListControllers.Request()) \
                        .add_done_callback(self.on_controllers)
                return
            wanted = interfaces_for(claimed_interfaces(self.controllers, self.states),
                                    self.joint_names, self.current)
            if wanted != self.current:
                self.busy = True
                self.parameters.set_parameters([Parameter(SERVO_INTERFACE, value=wanted)]) \
                    .add_done_callback(lambda future: self.on_set(future, wanted))

        def on_controllers(self, future) -> None:
            self.busy = False
            for controller in future.result().controller:
                if controller.state in ("active", "inactive"):
                    self.controllers[controller.name] = list(
                        controller.required_command_interfaces)
            self.follow()

        def on_set(self, future, wanted) -> None:
            self.busy = False
            result = future.result().results[0]
            active = sorted(c for c, s in self.states.items() if s == "active")
            if result.successful:
                self.get_logger().info(f"{SERVO_INTERFACE} {self.current} -> {wanted} "
                                       f"(active: {', '.join(active)})")
                self.current = wanted
                self.follow()        # the controllers may have switched again meanwhile
            else:
                self.get_logger().error(f"{self.target} refused {SERVO_INTERFACE} {wanted}: "
                                        f"{result.reason}")

    return ControllerFollower


def wait_for_state(topic: str, timeout: float) -> int:
    """0 once `topic` carries a finite position for every joint, 1 after `timeout` s."""
    import rclpy
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState

    node, started = rclpy.create_node("arm_sim_controllers_wait"), []
    node.create_subscription(JointState, topic,
                             lambda message: started.append(started_from(message.position)),
                             qos_profile_sensor_data)
    deadline = time.monotonic() + timeout
    while not any(started) and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    if any(started):
        node.get_logger().info(f"{topic}: the hardware has read the node's state; the "
                               "controllers may start")
        return 0
    node.get_logger().error(f"{topic}: no finite joint state within {timeout:g} s; the "
                            "controllers are not started (is arm_sim_node running, and "
                            "joint_state_broadcaster active?)")
    return 1


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(prog="arm_sim_controllers", description=__doc__.split("\n\n")[0],
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    jobs = parser.add_subparsers(dest="job", required=True, metavar="{follow,wait}")
    follow = jobs.add_parser("follow", help="set the node's servo.interface to what the "
                             "active controllers claim, at every switch")
    follow.add_argument("--node", default="/arm_sim", help="the arm_sim node (default /arm_sim)")
    follow.add_argument("--controller-manager", default="/controller_manager",
                        help="controller_manager's name (default /controller_manager)")
    wait = jobs.add_parser("wait", help="exit 0 once the hardware has read a finite state")
    wait.add_argument("--topic", default="/broadcaster/joint_states",
                      help="the joint_state_broadcaster's topic (default "
                           "/broadcaster/joint_states)")
    wait.add_argument("--timeout", type=float, default=60.0, help="wall seconds (default 60)")
    return parser


def main(argv=None) -> int:
    argv = sys.argv if argv is None else argv
    ours = argv[1:argv.index("--ros-args")] if "--ros-args" in argv else argv[1:]
    try:
        args = build_parser().parse_args(ours)
        import rclpy
        from rclpy.executors import ExternalShutdownException
    except UsageError as error:
        print(f"arm_sim_controllers: {one_line(error)}", file=sys.stderr)
        return REFUSED
    except ImportError as error:
        print(f"arm_sim_controllers: needs ROS 2 Jazzy sourced, with ros2_control ({error})",
              file=sys.stderr)
        return REFUSED
    rclpy.init(args=argv)
    try:
        if args.job == "wait":
            return wait_for_state(args.topic, args.timeout)
        rclpy.spin(follower_class()(args.node, args.controller_manager))
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        rclpy.try_shutdown()
    return DONE
