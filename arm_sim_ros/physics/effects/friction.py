"""Coulomb friction with a Stribeck curve and exact stiction, per joint.

Scene: `friction: {coulomb: [Fc1, Fc2], static: [Fs1, Fs2], stribeck_velocity: vs}` (N m,
N m, rad/s; static defaults to coulomb, vs to 0 = no Stribeck curve; Fs >= Fc >= 0).

A sliding joint i receives τᵢ = −sgn(q̇ᵢ)(Fcᵢ + (Fsᵢ − Fcᵢ) exp(−(q̇ᵢ/vs)²)). The sign is
the joint's mode (events.py), so within a mode the right-hand side is smooth; a joint whose
velocity reaches zero sticks while the torque that holds it still is within ±Fsᵢ: it is
then a constraint (q̇ᵢ = 0 exactly, position unchanged), its holding torque `lamᵢ` comes
out of the constrained solve (dynamics.py), and it slips when |lamᵢ| passes Fsᵢ, in the
direction of the net torque. Channel `friction_loss` = ∫Σ|τᵢ q̇ᵢ| dt (a loss).
"""
from __future__ import annotations

from math import exp

from ..model import ParameterError
from .base import Channel, Effect, Parameter

SLIDING = {"+": 1, "-": -1}


class Friction(Effect):
    name = "friction"
    switching = True
    parameters = (
        Parameter("coulomb", "pair", "N m", "non-negative",
                  description="sliding (Coulomb) friction torque per joint"),
        Parameter("static", "pair", "N m", "non-negative", default=None,
                  description="breakaway (static) friction torque per joint (default: coulomb)"),
        Parameter("stribeck_velocity", "float", "rad/s", "non-negative", default=0.0,
                  description="Stribeck velocity vs (0: no Stribeck curve)"),
    )

    def __init__(self, coulomb, static=None, stribeck_velocity=0.0):
        self.coulomb = tuple(coulomb)
        self.static = tuple(static) if static is not None else self.coulomb
        self.stribeck_velocity = float(stribeck_velocity)
        for i, (fc, fs) in enumerate(zip(self.coulomb, self.static)):
            if not fs >= fc:
                raise ParameterError(f"friction.static[{i}] = {fs:g} is below friction.coulomb"
                                     f"[{i}] = {fc:g}: breakaway needs Fs >= Fc (N m)")

    def curve(self, joint: int) -> bool:
        return self.stribeck_velocity > 0 and self.static[joint] > self.coulomb[joint]

    def constants(self, arm) -> dict:
        out = {"exp": exp, "INV_VS": 1.0 / self.stribeck_velocity if self.stribeck_velocity else 0.0}
        for i in (0, 1):
            out |= {f"FC{i + 1}": self.coulomb[i], f"FS{i + 1}": self.static[i],
                    f"DF{i + 1}": self.static[i] - self.coulomb[i]}
        return out

    def _magnitude(self, j: int) -> str:
        if self.curve(j - 1):
            return f"fr{j} = FC{j} + DF{j} * exp(-(u{j} * INV_VS) * (u{j} * INV_VS))"
        return f"fr{j} = FC{j}"

    def forces(self) -> list[str]:
        """Mode-free form (sgn of the stage velocity): the joint torque read-out only."""
        lines = []
        for j in (1, 2):
            lines += [self._magnitude(j), f"f{j} -= fr{j} * ((u{j} > 0.0) - (u{j} < 0.0))"]
        return lines + ["pf = fr1 * abs(u1) + fr2 * abs(u2)"]

    def mode_forces(self, mode) -> list[str]:
        lines, power = [], []
        for j in (1, 2):
            sign = SLIDING.get(mode[j - 1])
            if sign is None:          # stuck or resting on a hard limit: a constraint
                continue
            lines += [self._magnitude(j), f"f{j} {'-' if sign > 0 else '+'}= fr{j}"]
            power.append(f"{'' if sign > 0 else '-'}fr{j} * u{j}")
        return lines + [f"pf = {' + '.join(power) if power else '0.0'}".replace("+ -", "- ")]

    def channels(self):
        return (Channel("friction_loss", "pf", "loss"),)

    def guards(self, mode) -> list[tuple[str, str, int]]:
        """(g, kind, joint): the mode holds while every g >= 0."""
        out = []
        for i, code in enumerate(mode[:2]):
            j = i + 1
            if code in SLIDING:
                out.append((f"{'' if SLIDING[code] > 0 else '-'}u{j}", "stop", i))
            elif code == "stuck":
                out.append((f"FS{j} - abs(lam{j})", "slip", i))
        return out
