"""Effects a scene can call for, one module each, behind one interface (base.Effect).

`scene_effects` lists, in assembly order, exactly the effects a scene's values switch on;
an effect it does not list contributes no code, no state and no cost.
"""
from __future__ import annotations

from .actuator import POLICIES, Actuator
from .base import Channel, Effect
from .damping import Damping
from .gravity import Gravity

__all__ = ["POLICIES", "Actuator", "Channel", "Damping", "Effect", "Gravity", "scene_effects"]


def scene_effects(arm, gravity, damping, policy: str, constant_torque=(0.0, 0.0),
                  initial_positions=(0.0, 0.0), command=None) -> list[Effect]:
    """Gravity first (compensation reads its g1, g2), then the actuator, then the losses."""
    effects = []
    if gravity != 0.0:
        effects.append(Gravity(gravity))
    actuator = Actuator.for_policy(arm, policy, gravity, constant_torque, initial_positions,
                                   command)
    if actuator is not None:
        effects.append(actuator)
    if damping != 0.0:
        effects.append(Damping(damping))
    return effects
