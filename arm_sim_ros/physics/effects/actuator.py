"""The actuator: the torque policy's τ, added to f, its power τᵀq̇ booked as `work`.

Policies: constant τ, gravity compensation g(q) recomputed at every stage, the frozen
initial gravity torque g(q₀), and command (the latest torque from the topic, held),
alone or with gravity compensation on top. Compensation uses the true g (the gravity
effect's g1, g2) unless the scene gives the controller a model of its own (gc1, gc2).

Under a control loop (physics/sensing/loop.py: sensors the policy reads, or a command
delay) the policy's law is evaluated by the loop at the readings, once a step, and the
code reads the torque acting now (`acting`), as a command policy reads its command.
"""
from __future__ import annotations

from .base import Channel, Effect

POLICIES = ("zero", "constant", "gravity_compensation", "frozen_gravity", "command",
            "command_gravity_compensation", "setpoint")    # setpoint: the servo's (servo.py)
POLICY_TORQUE = {
    # policy: (torque lines, compensates gravity: needs the stage's gravity torque)
    "zero": ("t1 = 0.0; t2 = 0.0", False),
    "constant": ("t1 = TORQUE1; t2 = TORQUE2", False),
    "frozen_gravity": ("t1 = TORQUE1; t2 = TORQUE2", False),
    "gravity_compensation": ("t1 = g1; t2 = g2", True),
    "command": ("t1 = command[0]; t2 = command[1]", False),
    "command_gravity_compensation": ("t1 = command[0] + g1; t2 = command[1] + g2", True),
}
ACTING = POLICY_TORQUE["command"][0]     # under a control loop: the torque acting now


class Actuator(Effect):
    name = "actuator"
    drives = True

    def __init__(self, policy: str, fixed=None, command=None, compensation=None,
                 work_kind: str = "input", believed="g"):
        """`fixed`: the torque of constant and frozen_gravity; `command`: the list the
        command policies read at every stage (shared with the simulator); `compensation`:
        q -> the gravity torque the policy compensates (the believed one); `believed`: the
        prefix of that torque's names in the code (g, or gc for a controller model)."""
        self.policy, self.fixed, self.compensation = policy, fixed, compensation
        self.command = command if command is not None else [0.0, 0.0]
        lines, self.compensates = POLICY_TORQUE[policy]
        self.lines = lines.replace("+ g", f"+ {believed}").replace("= g", f"= {believed}")
        self.work_kind = work_kind   # "transfer" when windings turn electrical input into it
        self.acting = None           # a control loop's torque list (sensing/loop.py), or None

    def constants(self, arm) -> dict:
        if self.acting is not None:
            return {"command": self.acting}
        if self.fixed is None:
            return {"command": self.command}
        return {"TORQUE1": self.fixed[0], "TORQUE2": self.fixed[1], "command": self.command}

    def terms(self) -> list[str]:
        return [self.lines if self.acting is None else ACTING]

    def forces(self) -> list[str]:
        return ["f1 += t1",
                "f2 += t2"]

    def channels(self):
        return (Channel("work", "t1 * u1 + t2 * u2", self.work_kind),)

    def requested_torque(self, q):
        """τₐ as the policy asks for it at configuration q now (before limits and motors);
        under a control loop, the torque acting now."""
        return tuple(self.acting) if self.acting is not None else self.law(q)

    def law(self, q):
        """The policy's torque at (read) configuration q with the command held now."""
        if self.fixed is not None:
            return self.fixed
        t1, t2 = self.command if self.policy.startswith("command") else (0.0, 0.0)
        if self.compensates:
            g1, g2 = self.compensation(q)
            t1, t2 = t1 + g1, t2 + g2
        return t1, t2
