"""What ros2_control's controller_manager says, turned into what the node needs: each joint's
command interface (servo.interface) from the interfaces its active controllers claim, and
whether the hardware's state is one the controllers can start from.

Over ros-controls' topic-based hardware (joint_state_topic_hardware_interface) the node cannot
see the claims: the hardware sends every command interface of every joint each cycle, and a
controller deactivated leaves its last values in the interfaces it held. controller_manager
knows them; `arm_sim_controllers follow` asks it at each switch.
"""
from __future__ import annotations

from math import isfinite

# A joint claimed on more than one interface follows the first: a position controller that
# also claims velocity (a JointTrajectoryController's feed-forward) is a position one.
PRECEDENCE = ("position", "velocity", "effort")


def claimed_interfaces(controllers: dict, states: dict) -> set:
    """The "joint/interface" names the active controllers claim: `controllers` maps each
    controller's name to its command interfaces (ListControllers' required_command_interfaces,
    known once it is configured), `states` its lifecycle state (ControllerManagerActivity)."""
    return {name for controller, interfaces in controllers.items()
            if states.get(controller) == "active" for name in interfaces}


def interfaces_for(claimed, joint_names, current) -> list:
    """servo.interface for `claimed` ("joint/interface" names): per joint the first of
    PRECEDENCE it is claimed on; a joint no controller claims keeps its `current` one (the
    hardware goes on sending what the last controller left, as it would to a robot)."""
    out = []
    for joint, now in zip(joint_names, current):
        taken = [kind for kind in PRECEDENCE if f"{joint}/{kind}" in claimed]
        out.append(taken[0] if taken else now)
    return out


def unknown_active(controllers: dict, states: dict) -> list:
    """Active controllers whose command interfaces are not known yet (ask ListControllers)."""
    return sorted(c for c, state in states.items() if state == "active" and c not in controllers)


def started_from(positions) -> bool:
    """Whether a JointState's positions (a joint_state_broadcaster's: what the hardware has
    read) are there and finite: controllers activated before the hardware has read the
    node's first JointState start from NaN (a JointTrajectoryController holds NaN)."""
    return bool(positions) and all(isfinite(q) for q in positions)
