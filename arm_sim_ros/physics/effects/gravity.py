"""Gravity along −y with magnitude γ: g(q) = ∂V/∂q, V = γ (k1 sin q1 + k2 sin(q1 + q2))."""
from __future__ import annotations

from .. import model
from .base import Effect


class Gravity(Effect):
    name = "gravity"

    def __init__(self, gravity: float):
        self.gravity = gravity

    def constants(self, arm) -> dict:
        k1, k2 = arm.gravity_coefficients
        return {"G1": self.gravity * k1, "G2": self.gravity * k2}

    def terms(self) -> list[str]:
        return ["g2 = G2 * cos(q1 + q2)",
                "g1 = G1 * cos(q1) + g2"]

    def forces(self) -> list[str]:
        return ["f1 -= g1",
                "f2 -= g2"]

    def stored_energy(self, arm, q, extra) -> float:
        return model.potential_energy(arm, q, self.gravity)

    def lowest_stored_energy(self, arm) -> float:
        k1, k2 = arm.gravity_coefficients      # both links hanging straight down
        return -self.gravity * (abs(k1) + abs(k2))
