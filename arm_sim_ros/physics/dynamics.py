"""The right-hand side f(s), assembled from exactly the effects a scene calls for.

The rigid-body part (mass matrix, velocity-product torques, the LDLᵀ solve) is always
there; each effect (effects/) adds its lines in between, so a scene without gravity never
evaluates a gravity term (not even multiplied by zero) and a scene without damping has no
dissipation channel. The formulas are those of `model` written out once more as
straight-line code, because a function call per term would cost more than the physics on a
2-DOF arm; test_dynamics checks the two agree.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from math import cos, sin

from . import model
from .effects import Effect, scene_effects

RIGID_BODY = [
    "    c = cos(q2)",
    "    m11 = A + TWO_B * c",
    "    m12 = D + B * c",
    "    h = B * sin(q2)",
    "    f1 = h * (2.0 * u1 * u2 + u2 * u2)",   # -c(q, qd)
    "    f2 = -h * u1 * u1",
]
SOLVE = [
    "    l21 = m12 / m11",                      # LDL^T of the SPD mass matrix
    "    a2 = (f2 - l21 * f1) / (D - l21 * m12)",
    "    a1 = f1 / m11 - l21 * a2",
]


@dataclass
class Dynamics:
    """f(q1, q2, qd1, qd2) -> (qdd1, qdd2, *channel rates), plus what it was built from."""

    function: object
    source: str
    active: tuple[Effect, ...]        # the effects, in assembly order
    channels: tuple[str, ...]         # channel names, in state order
    channel_kinds: tuple[str, ...]    # "input" or "loss", per channel
    arm: model.ArmParameters
    command: list = field(default_factory=lambda: [0.0, 0.0])

    @property
    def effects(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.active)

    def applied_torque(self, q):
        """(tau1, tau2) as the policy applies it at configuration q now."""
        for effect in self.active:
            if effect.drives:
                return effect.applied_torque(self.arm, q)
        return 0.0, 0.0


def assemble(arm: model.ArmParameters, effects, command=None, label: str = "") -> Dynamics:
    """Generate and compile f from the rigid body and `effects`: their stage terms in list
    order, then their forces, inputs first (f = τ − c − g − D q̇ …)."""
    a, b, d = arm.inertia_coefficients
    namespace = {"cos": cos, "sin": sin, "A": a, "B": b, "TWO_B": 2.0 * b, "D": d}
    for effect in effects:
        namespace.update(effect.constants(arm))
    lines = ["def rhs(q1, q2, u1, u2):"] + RIGID_BODY
    for effect in effects:
        lines += ["    " + line for line in effect.terms()]
    for effect in sorted(effects, key=lambda e: not e.drives):
        lines += ["    " + line for line in effect.forces()]
    channels = [c for effect in effects for c in effect.channels()]
    lines += SOLVE + ["    return " + ", ".join(["a1", "a2"] + [c.rate for c in channels])]
    source = "\n".join(lines) + "\n"
    names = "+".join(e.name for e in effects) or "free"
    exec(compile(source, f"<rhs {label}, {names}>", "exec"), namespace)
    return Dynamics(namespace["rhs"], source, tuple(effects), tuple(c.name for c in channels),
                    tuple(c.kind for c in channels), arm,
                    command if command is not None else [0.0, 0.0])


def build_dynamics(arm: model.ArmParameters, gravity: float, damping: float, policy: str,
                   constant_torque=(0.0, 0.0), initial_positions=(0.0, 0.0)) -> Dynamics:
    """The dynamics of a scene with these values (effects whose value is 0 are absent)."""
    command = [0.0, 0.0]
    effects = scene_effects(arm, gravity, damping, policy, constant_torque, initial_positions,
                            command)
    return assemble(arm, effects, command, label=policy)
