"""Joint springs: τᵢ = −kᵢ (qᵢ − rᵢ); the stored ½ kᵢ (qᵢ − rᵢ)² counts in E.

Scene: `springs: {stiffness: [k1, k2], rest_positions: [r1, r2]}`.
"""
from __future__ import annotations

from math import sqrt

from ..stepping.stability import worst_stiffness
from .base import Effect, Parameter


class Springs(Effect):
    name = "springs"
    parameters = (
        Parameter("stiffness", "pair", "N m/rad", "non-negative",
                  description="spring constant per joint"),
        Parameter("rest_positions", "pair", "rad", default=(0.0, 0.0),
                  description="joint angle where the spring is relaxed"),
    )

    def __init__(self, stiffness, rest_positions=(0.0, 0.0)):
        self.spring_constants, self.rest_positions = tuple(stiffness), tuple(rest_positions)

    def constants(self, arm) -> dict:
        (k1, k2), (r1, r2) = self.spring_constants, self.rest_positions
        return {"SPRING1": k1, "SPRING2": k2, "REST1": r1, "REST2": r2}

    def forces(self) -> list[str]:
        return ["f1 -= SPRING1 * (q1 - REST1)",
                "f2 -= SPRING2 * (q2 - REST2)"]

    def stored_energy(self, arm, q, extra) -> float:
        (k1, k2), (r1, r2) = self.spring_constants, self.rest_positions
        return 0.5 * (k1 * (q[0] - r1) * (q[0] - r1) + k2 * (q[1] - r2) * (q[1] - r2))

    def frequency(self, arm) -> float:
        # M⁻¹K has eigenvalues below max(k) λmax(M⁻¹): ω ≤ sqrt(max(k) Λ).
        return sqrt(max(self.spring_constants) * worst_stiffness(arm))
