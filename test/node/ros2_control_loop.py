"""ros2_control as it drives the node, without ROS: controller_manager's cycle (read, switch,
update, write) at update_rate over ros-controls' JointStateTopicSystem, with the controllers
of config/ros2_controllers.yaml written as ros2_controllers writes them, and
arm_sim_controllers' follower, which sets servo.interface `delay` cycles after a switch.

What the sources say (ros2_control 4.46, ros2_controllers jazzy, topic_based_hardware_interfaces
1.1.0), kept here:
- the hardware's command interfaces hold NaN until a controller writes them; write() sends
  every command interface of every joint, each cycle (trigger_joint_command_threshold -1);
  read() takes the latest JointState by name;
- a switch is made at the start of a cycle: the old controller's on_deactivate, the new one's
  on_activate, then the new one's update and the hardware's write in the same cycle;
- JointTrajectoryController: on_activate holds the position read, or, with
  set_last_command_interface_value_as_state_on_activation (default true), the position its
  command interfaces hold where every joint's is set (what the controller active before left
  there); on_deactivate leaves the position command as it is and writes velocity 0 and
  effort 0;
- ForwardCommandController: its buffer is NaN at activation (it writes nothing until its
  first command); on_deactivate leaves its last values in the interfaces.
"""
from __future__ import annotations

import time

from arm_sim_ros.interface import JOINT_NAMES
from arm_sim_ros.tools.control.claims import claimed_interfaces, interfaces_for

NAN = float("nan")
INTERFACES = ("position", "velocity", "effort")


class TrajectoryController:
    """A JointTrajectoryController on `interface` (position: it claims position and velocity;
    effort: its PID with the yaml's gains), one goal at a time: a point of positions only
    (as `ros2 action send_goal` sends the docs' goal), which its splines join to where it
    holds by a straight line at constant velocity over `duration` s."""

    def __init__(self, name: str, config: dict, dt: float):
        self.name, self.config, self.dt = name, config, dt
        self.interface = config["command_interfaces"][0]
        self.claims = [f"{j}/{i}" for j in JOINT_NAMES for i in config["command_interfaces"]]

    def activate(self, hardware) -> None:
        q = [hardware.state[(j, "position")] for j in JOINT_NAMES]
        left = [hardware.commands[(j, "position")] for j in JOINT_NAMES]
        if (self.config.get("set_last_command_interface_value_as_state_on_activation", True)
                and self.interface == "position" and all(v == v for v in left)):
            q = left
        self.start = self.target = q
        self.duration, self.t, self.integral = 1.0, 0.0, [0.0, 0.0]

    def goal(self, target, duration: float) -> None:
        self.start, self.target, self.duration, self.t = self.reference()[0], list(target), duration, 0.0

    def reference(self):
        """(positions, velocities) of the trajectory now."""
        s, moving = min(self.t / self.duration, 1.0), self.t < self.duration
        return ([a + (b - a) * s for a, b in zip(self.start, self.target)],
                [(b - a) / self.duration if moving else 0.0
                 for a, b in zip(self.start, self.target)])

    def update(self, hardware) -> None:
        self.t += self.dt
        reference, rate = self.reference()
        for j, joint in enumerate(JOINT_NAMES):
            if self.interface == "position":
                hardware.commands[(joint, "position")] = reference[j]
                hardware.commands[(joint, "velocity")] = rate[j]
                continue
            gains = self.config["gains"][joint]
            error = reference[j] - hardware.state[(joint, "position")]
            self.integral[j] += error * self.dt
            held = min(max(gains["i"] * self.integral[j], gains["i_clamp_min"]),
                       gains["i_clamp_max"])
            hardware.commands[(joint, "effort")] = (
                gains["p"] * error + gains["d"] * (rate[j] - hardware.state[(joint, "velocity")])
                + held)

    def deactivate(self, hardware) -> None:
        for joint in JOINT_NAMES:
            for interface in ("velocity", "effort"):
                if f"{joint}/{interface}" in self.claims:
                    hardware.commands[(joint, interface)] = 0.0


class ForwardController:
    """A ForwardCommandController on `interface`: what it was last sent, from its first
    command on."""

    def __init__(self, name: str, config: dict, dt: float):
        self.name, self.interface = name, config["interface_name"]
        self.claims = [f"{j}/{self.interface}" for j in JOINT_NAMES]

    def activate(self, hardware) -> None:
        self.buffer = [NAN, NAN]

    def command(self, values) -> None:
        self.buffer = list(values)

    def update(self, hardware) -> None:
        if all(v != v for v in self.buffer):
            return
        for joint, value in zip(JOINT_NAMES, self.buffer):
            hardware.commands[(joint, self.interface)] = value

    def deactivate(self, hardware) -> None:
        self.buffer = [NAN, NAN]


class Manager:
    """controller_manager's cycle against `node` (a Wire or a Core below), one node tick per
    cycle; `follow(wanted)` sets servo.interface as arm_sim_controllers does, `delay` cycles
    after each switch."""

    def __init__(self, node, controllers: dict, delay: int = 0):
        self.node, self.controllers, self.delay = node, controllers, delay
        self.commands = {(j, i): NAN for j in JOINT_NAMES for i in INTERFACES}
        self.state = {(j, f): NAN for j in JOINT_NAMES for f in ("position", "velocity")}
        self.active, self.requested, self.due = None, None, None
        self.current = list(node.interfaces())
        self.torques, self.states, self.switched_at = [], [], []

    def switch(self, name: str):
        """The next cycle deactivates the active controller and activates `name`."""
        self.requested = name
        return self.controllers[name]

    def cycle(self) -> None:
        self.state.update(self.node.state())
        if self.requested is not None:
            if self.active is not None:
                self.active.deactivate(self)
            self.active, self.requested = self.controllers[self.requested], None
            self.active.activate(self)
            self.due = self.delay
            self.switched_at.append(len(self.torques))
        if self.due == 0:
            claimed = claimed_interfaces({c.name: c.claims for c in self.controllers.values()},
                                         {self.active.name: "active"})
            self.current = interfaces_for(claimed, JOINT_NAMES, self.current)
            self.node.follow(self.current)
        self.due = None if self.due is None or self.due == 0 else self.due - 1
        if self.active is not None:
            self.active.update(self)
        self.node.command([[self.commands[(j, f)] for j in JOINT_NAMES] for f in INTERFACES])
        position, velocity, effort = self.node.tick()
        self.torques.append(effort)
        self.states.append(position + velocity)

    def run(self, seconds: float, dt: float) -> None:
        for _ in range(round(seconds / dt)):
            self.cycle()


class Core:
    """The node's core, called as its transports call it."""

    def __init__(self, core):
        self.core = core

    def interfaces(self):
        return self.core.config.values["servo.interface"]

    def state(self) -> dict:
        y = self.core.sim.state
        return {(j, f): y[k + 2 * (f == "velocity")] for k, j in enumerate(JOINT_NAMES)
                for f in ("position", "velocity")}

    def follow(self, interfaces) -> None:
        self.core.set_parameters({"servo.interface": list(interfaces)})

    def command(self, fields) -> None:
        assert self.core.on_joint_state_command(list(JOINT_NAMES), *fields) is None

    def tick(self):
        data = self.core.tick(0.0)
        return list(data.position), list(data.velocity), list(data.effort)


class Wire:
    """The dds node on the wire: commands as the hardware writes them (reliable, keep-last 1),
    joint_states as it reads them (best effort), servo.interface through the parameter
    service; the node runs in this thread, ticking once per cycle."""

    def __init__(self, node, commands, states, setter, timeout: float):
        self.dds, self.commands, self.states, self.setter = node, commands, states, setter
        self.timeout, self.latest = timeout, None

    def interfaces(self):
        return self.dds.core.config.values["servo.interface"]

    def state(self) -> dict:
        if self.latest is None:       # before the first tick: the node's state as published
            self.tick()
        names = list(self.latest.name)
        return {(j, f): list(getattr(self.latest, f))[names.index(j)] for j in JOINT_NAMES
                for f in ("position", "velocity")}

    def follow(self, interfaces) -> None:
        from arm_sim_ros.node.services import parameter_services as ps
        from node.test_dds_services import param
        (result,) = self.setter.call(self.dds, parameters=[
            param("servo.interface", ps.STRING_ARRAY, list(interfaces))]).results
        assert result.successful, result.reason

    def command(self, fields) -> None:
        from arm_sim_ros.node.wire import messages as msg
        position, velocity, effort = fields
        self.commands.write(msg.JointState(name=list(JOINT_NAMES), position=position,
                                           velocity=velocity, effort=effort))
        assert self.dds.take_commands(timeout=self.timeout) == 1

    def tick(self):
        from arm_sim_ros.node.wire import messages as msg
        self.dds.tick()
        deadline, taken = time.monotonic() + self.timeout, []
        while not taken and time.monotonic() < deadline:
            taken = [s for s in self.states.take(N=10) if isinstance(s, msg.JointState)]
        assert taken, "no joint_states"
        self.latest = taken[-1]
        return list(self.latest.position), list(self.latest.velocity), list(self.latest.effort)
