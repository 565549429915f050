"""The actuator: the torque policy's τ, added to f, its power τᵀq̇ booked as `work`.

Policies: constant τ, gravity compensation g(q) recomputed at every stage, the frozen
initial gravity torque g(q₀), and command (the latest torque from the topic, held),
alone or with gravity compensation on top.
"""
from __future__ import annotations

from .. import model
from .base import Channel, Effect

POLICIES = ("zero", "constant", "gravity_compensation", "frozen_gravity", "command",
            "command_gravity_compensation")
POLICY_TORQUE = {
    # policy: (torque lines, compensates gravity: needs the stage's g1, g2)
    "constant": ("t1 = TORQUE1; t2 = TORQUE2", False),
    "frozen_gravity": ("t1 = TORQUE1; t2 = TORQUE2", False),
    "gravity_compensation": ("t1 = g1; t2 = g2", True),
    "command": ("t1 = command[0]; t2 = command[1]", False),
    "command_gravity_compensation": ("t1 = command[0] + g1; t2 = command[1] + g2", True),
}


class Actuator(Effect):
    name = "actuator"
    drives = True

    def __init__(self, policy: str, gravity: float, fixed=None, command=None):
        """`fixed`: the torque of constant and frozen_gravity; `command`: the list the
        command policies read at every stage (shared with the simulator)."""
        self.policy, self.gravity, self.fixed = policy, gravity, fixed
        self.command = command if command is not None else [0.0, 0.0]
        self.lines, self.compensates = POLICY_TORQUE[policy]

    @classmethod
    def for_policy(cls, arm, policy: str, gravity: float, constant_torque, initial_positions,
                   command) -> "Actuator | None":
        """The actuator a policy needs, or None when it applies no torque at all."""
        if policy not in POLICIES:
            raise ValueError(f"unknown policy {policy!r}; choose one of {', '.join(POLICIES)}")
        if policy == "zero" or (policy == "gravity_compensation" and gravity == 0.0):
            return None                      # compensating absent gravity is no torque
        if policy == "command_gravity_compensation" and gravity == 0.0:
            policy = "command"
        fixed = (tuple(constant_torque) if policy == "constant" else
                 model.gravity_torque(arm, initial_positions, gravity)
                 if policy == "frozen_gravity" else None)
        return cls(policy, gravity, fixed, command)

    def constants(self, arm) -> dict:
        if self.fixed is None:
            return {"command": self.command}
        return {"TORQUE1": self.fixed[0], "TORQUE2": self.fixed[1], "command": self.command}

    def terms(self) -> list[str]:
        return [self.lines]

    def forces(self) -> list[str]:
        return ["f1 += t1",
                "f2 += t2"]

    def channels(self):
        return (Channel("work", "t1 * u1 + t2 * u2", "input"),)

    def applied_torque(self, arm, q):
        """τ as the policy applies it at configuration q now."""
        if self.fixed is not None:
            return self.fixed
        t1, t2 = self.command if self.policy.startswith("command") else (0.0, 0.0)
        if self.compensates:
            g1, g2 = model.gravity_torque(arm, q, self.gravity)
            t1, t2 = t1 + g1, t2 + g2
        return t1, t2
