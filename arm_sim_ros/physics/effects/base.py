"""The interface every effect implements: what it adds to f(s), to the energy books, and to
the stability planner.

The right-hand side is straight-line code assembled from exactly the effects a scene names
(dynamics.py): an effect contributes source lines, never a function call per stage, because
a call per term would cost more than the physics of a 2-DOF arm. The generated function sees
the stage's q1, q2, u1, u2 (angles and velocities), accumulates the generalized force in
f1, f2 (f = τ − c − g − D q̇ …) and solves M a = f at the end.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Channel:
    """An energy flow integrated at the same RK stages as the state.

    `rate` is an expression of the stage's variables; `kind` says how it enters the
    balance E(t) − E(0) = Σ inputs − Σ losses.
    """

    name: str
    rate: str
    kind: str          # "input" or "loss"


class Effect:
    """One physical effect. Subclasses override only what they contribute."""

    name = ""
    drives = False     # an input (the actuator): its force is added before the passive ones

    def constants(self, arm) -> dict:
        """Names the generated code reads; values may be per-arm arrays (Batch)."""
        return {}

    def terms(self) -> list[str]:
        """Lines computing the stage's quantities (gravity's g1, g2, the actuator's t1, t2)."""
        return []

    def forces(self) -> list[str]:
        """Lines adding this effect's generalized force to f1, f2."""
        return []

    def channels(self) -> tuple[Channel, ...]:
        return ()

    def stored_energy(self, arm, q) -> float:
        """Energy this effect stores at configuration q, counted in E (0 if it stores none)."""
        return 0.0

    def stiffness(self, arm) -> float:
        """The largest decay rate (1/s) it adds on the negative real axis, at any pose: what
        the sub-step planner keeps h times under the integrator's real stability limit."""
        return 0.0
