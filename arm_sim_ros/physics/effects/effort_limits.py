"""Effort limits: the requested joint torque τₐ (the policy's output, compensation
included) is clamped to ±eᵢ before it acts, or before the motor driver with windings.

Scene: `effort_limits: [e1, e2]` (N m). MIN/MAX are the builtins for one arm and numpy's
elementwise minimum/maximum in Batch.

When the request depends on the state (a gravity-compensating policy) the clamp is a
switching effect (`switching`, set by scene_effects): each joint's clamp is a mode (0
passes the request `ta`, 1/-1 holds ±eᵢ, the fifth entry of events.py's mode) whose end is
located inside the step like a friction switch, so RK4 keeps its order across it. A
request constant within the step (constant, frozen, command) keeps MIN/MAX: the clamp is
constant there, smooth by construction.
"""
from __future__ import annotations

from .base import Effect, Parameter, clamp_guards, clamp_lines

EFFORT = 0                 # where the effort clamps' modes sit in the clamp modes


class EffortLimits(Effect):
    name = "effort_limits"
    drives = True
    parameter = Parameter("effort_limits", "pair", "N m", "positive",
                          description="largest torque each joint's actuator can apply")

    def __init__(self, limits, switching: bool = False):
        self.limits = tuple(limits)
        self.switching = switching          # the request depends on the state: located

    def constants(self, arm) -> dict:
        return {"EFFORT1": self.limits[0], "EFFORT2": self.limits[1]}

    def terms(self) -> list[str]:
        return ["t1 = MIN(MAX(t1, -EFFORT1), EFFORT1)",
                "t2 = MIN(MAX(t2, -EFFORT2), EFFORT2)"]

    def mode_terms(self, mode) -> list[str]:
        if not self.switching:
            return self.terms()
        lines = []
        for i in (0, 1):
            j, clamp = i + 1, mode[4][EFFORT + i]
            lines += [f"ta{j} = t{j}"] + (clamp_lines(f"ta{j}", f"t{j}", f"EFFORT{j}", clamp)
                                          if clamp else [])
        return lines

    def guards(self, mode) -> list[tuple[str, str, int]]:
        return [g for i in (0, 1) for g in
                clamp_guards(f"ta{i + 1}", f"EFFORT{i + 1}", mode[4][EFFORT + i], "effort", i)]

    def clamp(self, torque):
        return tuple(min(max(t, -e), e) for t, e in zip(torque, self.limits))
