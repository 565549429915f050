"""Effects a scene can call for, one module each, behind one interface (base.Effect).

`scene_effects` lists, in assembly order, exactly the effects a scene names: an effect it
does not list contributes no code, no state, no channel and no cost.
"""
from __future__ import annotations

from functools import partial

from .. import model
from .actuator import POLICIES, Actuator
from .base import Channel, Effect, Parameter, validate
from .controller_model import ControllerModel
from .damping import Damping
from .effort_limits import EffortLimits
from .friction import Friction
from .gravity import Gravity
from .joint_limits import CompliantLimits, HardLimits, JointLimits
from .motors import Motors
from .payload import Payload
from .servo import SERVO_POLICIES, Servo
from .springs import Springs

__all__ = ["POLICIES", "Actuator", "Channel", "CompliantLimits", "ControllerModel", "Damping",
           "Effect", "EffortLimits", "Friction", "Gravity", "HardLimits", "JointLimits", "Motors",
           "Parameter", "Payload", "Servo", "Springs", "BUILDERS", "MAPPING_EFFECTS", "scene_effects",
           "validate"]

# Scene keys whose value is a mapping of the effect's parameters.
MAPPING_EFFECTS = {"springs": Springs, "payload": Payload, "motors": Motors,
                   "controller_model": ControllerModel, "friction": Friction,
                   "joint_limits": JointLimits, "servo": Servo}
# How a scene's validated mapping becomes the effect (with its cross-checks: windings all
# three or none, Fs >= Fc, lower < upper, restitution or stiffness).
BUILDERS = {"motors": Motors, "friction": Friction, "joint_limits": JointLimits.make,
            "servo": Servo}
COMPENSATING = ("gravity_compensation", "command_gravity_compensation")


def scene_effects(scene, command=None, acting=None) -> list[Effect]:
    """The scene's effects in assembly order: gravity (its g1, g2 feed compensation), the
    controller's model, the drive chain (policy → effort limits → motor windings), then the
    passive forces. `command` is the list the command policies read; `acting`, under a
    control loop (physics/sensing/loop.py), the torque list the drive reads instead (the
    loop evaluates the policy, the controller's model included, at the readings)."""
    arm, effects = scene.arm, []
    if scene.gravity != 0.0:
        effects.append(Gravity(scene.gravity))
    motors = Motors(**scene.motors) if scene.motors is not None else None
    windings = motors is not None and motors.windings
    believed = (ControllerModel(scene.links, scene.gravity, _payload_mass(scene),
                                **scene.controller_model)
                if scene.controller_model is not None else None)
    actuator = (_actuator(scene, arm, believed, command, windings) if scene.servo is None
                else _servo(scene, arm, believed, command, windings))
    # A request that depends on the state (compensation) crosses its clamps inside a step:
    # they switch as located events then; else the clamp is constant within the step.
    located = actuator is not None and actuator.compensates and acting is None
    if actuator is not None:
        if believed is not None and located:
            effects.append(believed)
        actuator.acting = acting
        effects.append(actuator)
        if scene.effort_limits is not None and scene.servo is None:   # the servo clamps
            effects.append(EffortLimits(scene.effort_limits, switching=located))
    if windings and motors.voltage_limit is not None:
        motors.switching = located
    if motors is not None:
        effects.append(motors)       # armature only: no code; windings: the driver and currents
    if scene.springs is not None:
        effects.append(Springs(**scene.springs))
    if scene.damping != 0.0:
        effects.append(Damping(scene.damping))
    if scene.payload is not None:
        effects.append(Payload(scene.payload["mass"]))
    if scene.friction is not None:                 # non-smooth: switched by events.py
        effects.append(Friction(**scene.friction))
    if scene.joint_limits is not None:
        effects.append(JointLimits.make(**scene.joint_limits))
    return effects


def _payload_mass(scene) -> float:
    return scene.payload["mass"] if scene.payload is not None else 0.0


def _believed_torque(scene, arm, believed):
    """q -> the gravity torque the controller believes: model.gravity_torque of its arm and
    gravity (a partial: the compiled control loop reads them, compiled/sensed.py)."""
    if believed is not None:
        return partial(model.gravity_torque, believed.arm, gravity=believed.gravity)
    return partial(model.gravity_torque, arm, gravity=scene.gravity)


def _servo(scene, arm, believed, command, windings) -> Servo:
    """The joint servos, the actuator of a scene with `servo` (its policy: setpoint or a
    command one); compensation feeds the believed gravity torque forward."""
    compensates = scene.policy == "command_gravity_compensation" and (
        believed.gravity if believed is not None else scene.gravity) != 0.0
    return Servo(**scene.servo, policy=scene.policy if compensates or scene.policy != (
                     "command_gravity_compensation") else "command",
                 setpoint=scene.setpoint, initial_positions=scene.initial_positions,
                 effort_limits=scene.effort_limits, command=command,
                 compensation=_believed_torque(scene, arm, believed),
                 work_kind="transfer" if windings else "input",
                 believed="gc" if believed is not None else "g", step_size=scene.step_size)


def _actuator(scene, arm, believed, command, windings) -> Actuator | None:
    """The policy's actuator, or None when it applies no torque and no winding needs one."""
    policy = scene.policy
    gravity = believed.gravity if believed is not None else scene.gravity
    if policy in COMPENSATING and gravity == 0.0:   # compensating absent gravity: no torque
        policy = "zero" if policy == "gravity_compensation" else "command"
    if policy == "zero" and not windings:
        return None
    believed_torque = _believed_torque(scene, arm, believed)
    fixed = (tuple(scene.constant_torque) if policy == "constant" else
             believed_torque(scene.initial_positions) if policy == "frozen_gravity" else None)
    return Actuator(policy, fixed, command, compensation=believed_torque,
                    work_kind="transfer" if windings else "input",
                    believed="gc" if believed is not None else "g")
