"""Controllers switched live, as a ros2_control user switches them: controller_manager's cycle
over the topic-based hardware (ros2_control_loop.py) with the controllers of
config/ros2_controllers.yaml, and arm_sim_controllers' follower setting servo.interface a
few cycles after each switch. Each goal or command reaches its target, no command is
refused, and no switch makes the torque jump. On the dds node on the wire (domain 148) and
on the node's core for every pair of interfaces."""
from __future__ import annotations

import logging
from itertools import permutations

import pytest
import yaml
from cyclonedds.core import Policy, Qos
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from arm_sim_ros.interface import JOINT_NAMES
from arm_sim_ros.node.core import ArmSimCore
from arm_sim_ros.node.params.parameters import resolve_parameters
from arm_sim_ros.node.wire import messages as msg
from node.ros2_control_loop import Core, ForwardController, Manager, TrajectoryController, Wire
from node.test_dds_services import clients, start
from node.test_node_dds import TIMEOUT, wait_until
from node.test_ros2_control import CONTROLLERS

DT = 1.0 / CONTROLLERS["controller_manager"]["ros__parameters"]["update_rate"]
NAMES = {"position": "position_trajectory_controller", "effort": "effort_trajectory_controller",
         "velocity": "forward_velocity_controller"}
GOAL = CONTROLLERS[NAMES["position"]]["ros__parameters"]["constraints"]["shoulder_joint"]["goal"]
DELAY = 2        # cycles from a switch to servo.interface set (the follower's answer)
BUMP = 0.5       # N m: the most a joint's torque may change in a tick of a switch
PARAMETERS = {"scene": "servo_hold", "policy": "command_gravity_compensation"}  # the launch's


def controllers(**changed) -> dict:
    """The shipped controllers, each trajectory controller's parameters with `changed`."""
    return {name: TrajectoryController(name, CONTROLLERS[name]["ros__parameters"] | changed, DT)
            if "trajectory" in name else
            ForwardController(name, CONTROLLERS[name]["ros__parameters"], DT)
            for name in NAMES.values()}


def drive(manager, interface: str, target) -> float:
    """Switch to the controller on `interface`, then its goal (a JTC: to the pose `target`
    in 2 s, then its goal_time) or command (forward velocity: `target` rad/s for 1 s, then
    0 for 0.5 s: the next controller takes over an arm at rest, as a holding one would);
    how far the arm was from it."""
    controller = manager.switch(NAMES[interface])
    manager.run(0.3, DT)
    if interface == "velocity":
        controller.command(target)
        manager.run(1.0, DT)
        error = max(abs(u - t) for u, t in zip(manager.states[-1][2:], target))
        controller.command([0.0, 0.0])
        manager.run(0.5, DT)
        return error
    controller.goal(target, 2.0)
    manager.run(3.0, DT)
    return max(abs(q - t) for q, t in zip(manager.states[-1][:2], target))


def jumps(manager) -> list:
    """The largest change of a joint torque in the ticks from each switch to the follower's
    set and two more: the node's own doing (the controllers hold through a switch)."""
    torques = manager.torques
    return [max(abs(b - a) for k in range(at, at + DELAY + 3)
                for a, b in zip(torques[k - 1], torques[k])) for at in manager.switched_at[1:]]


TARGETS = {"position": [0.8, -0.4], "effort": [0.3, 0.6], "velocity": [0.3, -0.2]}


def test_position_effort_velocity_position_on_the_wire():
    """The tour of the issue, on the dds node: the hardware's JointState commands (every
    interface of every joint) and its joint_states subscription on the wire, servo.interface
    set through the parameter service."""
    node, p = start(148, **PARAMETERS)
    commands = DataWriter(p, Topic(p, "rt/joint_commands", msg.JointState), qos=Qos(
        Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
        Policy.Durability.Volatile, Policy.History.KeepLast(1)))
    states = DataReader(p, Topic(p, "rt/joint_states", msg.JointState), qos=Qos(
        Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(5)))
    wait_until(lambda: msg.matched(commands) and msg.matched(states), "not matched")
    setter = clients(p, "set_parameters")
    manager = Manager(Wire(node, commands, states, setter, TIMEOUT), controllers(), DELAY)
    errors = {}
    for step, (interface, target) in enumerate([("position", [0.8, -0.4]),
                                                ("effort", [0.3, 0.6]),
                                                ("velocity", [0.3, -0.2]),
                                                ("position", [0.5, 0.2])]):
        errors[step, interface] = drive(manager, interface, target)
    assert node.core.refused_commands == 0
    assert all(error < GOAL for error in errors.values()), errors
    assert max(jumps(manager)) < BUMP
    assert node.core.config.values["servo.interface"] == ["position", "position"]


def core_manager(delay: int = DELAY, changed=None, **parameters) -> Manager:
    core = ArmSimCore(resolve_parameters(PARAMETERS | parameters),
                      logging.getLogger("test_switching"), wall_clock=lambda: 0.0,
                      start_stamp_ns=0)
    return Manager(Core(core), controllers(**(changed or {})), delay)


@pytest.mark.parametrize("from_commands", [False, True], ids=["as_shipped", "default_true"])
def test_a_position_controller_back_after_another_holds_the_arm_where_it_is(from_commands):
    """position JTC -> velocity -> position JTC: the shipped controllers start from the
    state read (set_last_command_interface_value_as_state_on_activation false) and hold the
    arm where the velocity controller left it; ros2_controllers' default (true) starts from
    what the position interfaces hold, the first JTC's last goal, and pulls the arm back
    there, 0.3 rad (against a real controller_manager: 0.5 rad, at 50 N m)."""
    manager = core_manager(changed={"set_last_command_interface_value_as_state_on_activation":
                                    True} if from_commands else {})
    drive(manager, "position", TARGETS["position"])
    drive(manager, "velocity", TARGETS["velocity"])
    left = manager.states[-1][:2]
    manager.switch(NAMES["position"])
    manager.run(1.0, DT)
    held = TARGETS["position"] if from_commands else left
    assert max(abs(q - p) for q, p in zip(manager.states[-1][:2], held)) < GOAL * 2
    assert max(abs(q - p) for q, p in zip(TARGETS["position"], left)) > 0.25   # apart


@pytest.mark.parametrize("before, after", list(permutations(NAMES, 2)))
def test_every_switch_between_interfaces_is_bumpless_and_the_new_controller_drives(
        before, after, caplog):
    manager = core_manager()
    with caplog.at_level(logging.WARNING):
        assert drive(manager, before, TARGETS[before]) < GOAL
        assert drive(manager, after, TARGETS[after]) < GOAL
    assert manager.node.core.refused_commands == 0
    assert max(jumps(manager)) < BUMP
    assert manager.node.core.config.values["servo.interface"] == [after, after]
    # no warning in ordinary goals and switches
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]


@pytest.mark.parametrize("interface, peaks", [("position", (21.1, 4.8)),
                                              ("effort", (23.1, 7.7))])
def test_the_guides_goal_asks_the_torque_a_real_controller_manager_asked(interface, peaks):
    """The launch's goal as the guide sends it (positions only, 2 s: [0.3, 0.6] -> [0.8,
    -0.4] rad): the largest |effort| in joint_states per joint, as measured against a real
    controller_manager 4.46 in real time (docs/guides/servos.md)."""
    manager = core_manager(delay=0, **{"servo.interface": [interface] * 2})
    controller = manager.switch(NAMES[interface])
    manager.run(0.5, DT)
    start = len(manager.torques)
    controller.goal([0.8, -0.4], 2.0)
    manager.run(3.0, DT)
    assert tuple(round(max(abs(t[j]) for t in manager.torques[start:]), 1)
                 for j in (0, 1)) == peaks
