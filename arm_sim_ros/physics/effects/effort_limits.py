"""Effort limits: the requested joint torque τₐ (the policy's output, compensation
included) is clamped to ±eᵢ before it acts, or before the motor driver with windings.

Scene: `effort_limits: [e1, e2]` (N m). MIN/MAX are the builtins for one arm and numpy's
elementwise minimum/maximum in Batch.
"""
from __future__ import annotations

from .base import Effect, Parameter


class EffortLimits(Effect):
    name = "effort_limits"
    drives = True
    parameter = Parameter("effort_limits", "pair", "N m", "positive",
                          description="largest torque each joint's actuator can apply")

    def __init__(self, limits):
        self.limits = tuple(limits)

    def constants(self, arm) -> dict:
        return {"EFFORT1": self.limits[0], "EFFORT2": self.limits[1]}

    def terms(self) -> list[str]:
        return ["t1 = MIN(MAX(t1, -EFFORT1), EFFORT1)",
                "t2 = MIN(MAX(t2, -EFFORT2), EFFORT2)"]

    def clamp(self, torque):
        return tuple(min(max(t, -e), e) for t, e in zip(torque, self.limits))
