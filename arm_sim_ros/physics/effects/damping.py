"""Viscous joint damping D = d I: τ = −d q̇, its power d |q̇|² booked as `dissipated`."""
from __future__ import annotations

from ..stability import worst_stiffness
from .base import Channel, Effect


class Damping(Effect):
    name = "damping"

    def __init__(self, damping: float):
        self.damping = damping

    def constants(self, arm) -> dict:
        return {"DAMPING": self.damping}

    def forces(self) -> list[str]:
        return ["f1 -= DAMPING * u1",
                "f2 -= DAMPING * u2"]

    def channels(self):
        return (Channel("dissipated", "DAMPING * (u1 * u1 + u2 * u2)", "loss"),)

    def stiffness(self, arm) -> float:
        # −d M⁻¹ q̇ has eigenvalues −d λᵢ(M⁻¹); the worst over every elbow angle.
        return self.damping * worst_stiffness(arm)
