"""arm_sim_controllers follow on rclpy, where ROS 2 Jazzy with ros2_control is sourced (skips
cleanly elsewhere): a controller_manager stand-in publishes ~/activity and serves
list_controllers as 4.46 does, and the rclpy node's servo.interface follows each switch."""
import os
import time

import pytest

rclpy = pytest.importorskip("rclpy")
cm_msgs = pytest.importorskip("controller_manager_msgs.msg")

from controller_manager_msgs.srv import ListControllers  # noqa: E402
from lifecycle_msgs.msg import State  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402

from arm_sim_ros.node.transports.rclpy_transport import ArmSimNode  # noqa: E402
from arm_sim_ros.tools.control.follower import follower_class  # noqa: E402
from tools.test_control import KNOWN  # noqa: E402

TIMEOUT = 10.0
TAG = (f"<CycloneDDS><Domain><Discovery><Tag>arm_sim_test_control_{os.getpid()}</Tag>"
       "</Discovery></Domain></CycloneDDS>")


class Manager:
    """controller_manager's ~/activity (reliable, transient-local, depth 1) and
    list_controllers, as 4.46 serves them."""

    def __init__(self, context):
        self.node = rclpy.create_node("controller_manager", context=context)
        self.states = {name: "inactive" for name in KNOWN}
        self.activity = self.node.create_publisher(
            cm_msgs.ControllerManagerActivity, "~/activity",
            QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.asked = 0
        self.node.create_service(ListControllers, "~/list_controllers", self.list)

    def list(self, request, response):
        self.asked += 1
        response.controller = [cm_msgs.ControllerState(
            name=name, state=state, required_command_interfaces=KNOWN[name],
            claimed_interfaces=KNOWN[name] if state == "active" else [])
            for name, state in self.states.items()]
        return response

    def switch(self, active: str) -> None:
        self.states = {name: "active" if name == active else "inactive" for name in KNOWN}
        ids = {"active": State.PRIMARY_STATE_ACTIVE, "inactive": State.PRIMARY_STATE_INACTIVE}
        self.activity.publish(cm_msgs.ControllerManagerActivity(controllers=[
            cm_msgs.NamedLifecycleState(name=name, state=State(id=ids[state], label=state))
            for name, state in self.states.items()]))


def test_the_nodes_servo_interface_follows_every_switch(monkeypatch):
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("CYCLONEDDS_URI", TAG)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=31)
    executor = SingleThreadedExecutor(context=context)
    try:
        node = ArmSimNode(context=context, parameter_overrides=[
            Parameter("scene", value="servo_hold")])
        manager = Manager(context)
        follower = follower_class()("/arm_sim", "/controller_manager", context=context)
        for member in (node, manager.node, follower):
            executor.add_node(member)

        def spin_until(condition):
            deadline = time.monotonic() + TIMEOUT
            while not condition():
                assert time.monotonic() < deadline, "not followed"
                executor.spin_once(timeout_sec=0.01)

        spin_until(lambda: follower.current is not None)
        for active, interface in (("effort_trajectory_controller", "effort"),
                                  ("forward_velocity_controller", "velocity"),
                                  ("position_trajectory_controller", "position"),
                                  ("forward_effort_controller", "effort")):
            manager.switch(active)
            spin_until(lambda: node.core.config.values["servo.interface"] == [interface] * 2)
        assert manager.asked == 1            # each controller's interfaces asked once
        assert node.core.refused_commands == 0
    finally:
        executor.shutdown()
        rclpy.shutdown(context=context)
