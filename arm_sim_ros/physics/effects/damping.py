"""Viscous joint damping: τᵢ = −dᵢ q̇ᵢ (`damping: d` or `damping: [d1, d2]`), its power
Σ dᵢ q̇ᵢ² booked as `dissipated`."""
from __future__ import annotations

from ..stepping.stability import worst_stiffness
from .base import Channel, Effect


class Damping(Effect):
    name = "damping"

    def __init__(self, damping):
        """A scalar d (D = d I, one constant in the code) or a pair (d1, d2)."""
        self.damping = damping
        self.per_joint = isinstance(damping, tuple)

    def constants(self, arm) -> dict:
        if self.per_joint:
            return {"DAMPING1": self.damping[0], "DAMPING2": self.damping[1]}
        return {"DAMPING": self.damping}

    def forces(self) -> list[str]:
        if self.per_joint:
            return ["f1 -= DAMPING1 * u1",
                    "f2 -= DAMPING2 * u2"]
        return ["f1 -= DAMPING * u1",
                "f2 -= DAMPING * u2"]

    def channels(self):
        if self.per_joint:
            return (Channel("dissipated", "DAMPING1 * u1 * u1 + DAMPING2 * u2 * u2", "loss"),)
        return (Channel("dissipated", "DAMPING * (u1 * u1 + u2 * u2)", "loss"),)

    def stiffness(self, arm) -> float:
        # −M⁻¹D q̇ has eigenvalues within −max(d) λ(M⁻¹); the worst over every elbow angle.
        largest = max(self.damping) if self.per_joint else self.damping
        return largest * worst_stiffness(arm)
