"""Joint limits, hard or compliant.

Scene: `joint_limits: {lower: [l1, l2], upper: [u1, u2], restitution: e}` (hard, e in
[0, 1], the default e = 0) or `{lower, upper, stiffness: k, damping: c}` (compliant).

Hard: a joint never passes its limit. Arriving with velocity v (located inside the step,
events.py) it leaves with −e v, by an impulse along that joint (the other joint's velocity
changes through M's coupling); the kinetic energy lost, ½ (1 − e²) v² / (M⁻¹)ᵢᵢ, goes to
the channel `impact_loss`. Pushed into the limit it rests there: the joint is a constraint
whose torque `lamᵢ` (dynamics.py) pushes away, until it would have to pull.

Compliant: beyond the limit by δ the joint receives τ = −k δ − c δ̇ (only while beyond,
entering and leaving located as events); ½ k δ² counts in E, the damper's c δ̇² in
`dissipated`. The stiffness matters only while a joint is beyond its limit, so it feeds the
sub-step planner only then (events.py: `engaged_stiffness`, `engaged_frequency`).
"""
from __future__ import annotations

from math import sqrt

from ..model import ParameterError
from ..stepping.stability import worst_stiffness
from .base import Channel, Effect, Parameter


class JointLimits(Effect):
    name = "joint_limits"
    switching = True
    parameters = (
        Parameter("lower", "pair", "rad", description="lowest angle per joint"),
        Parameter("upper", "pair", "rad", description="highest angle per joint"),
        Parameter("restitution", "float", "1", "non-negative", default=None,
                  description="hard limits: coefficient of restitution e in [0, 1] (default 0)"),
        Parameter("stiffness", "float", "N m/rad", "positive", default=None,
                  description="compliant limits: stiffness k beyond the limit"),
        Parameter("damping", "float", "N m s/rad", "non-negative", default=None,
                  description="compliant limits: damping c beyond the limit"),
    )
    hard = True

    def __init__(self, lower, upper):
        self.lower, self.upper = tuple(lower), tuple(upper)
        for i, (lo, hi) in enumerate(zip(self.lower, self.upper)):
            if not lo < hi:
                raise ParameterError(f"joint_limits.lower[{i}] = {lo:g} must be below "
                                     f"joint_limits.upper[{i}] = {hi:g} (rad)")

    @staticmethod
    def make(lower, upper, restitution=None, stiffness=None, damping=None) -> "JointLimits":
        """Hard limits, or compliant ones when a stiffness is given; bad sets refused."""
        if stiffness is None:
            if damping is not None:
                raise ParameterError("joint_limits.damping needs joint_limits.stiffness "
                                     "(compliant limits); hard limits take restitution")
            return HardLimits(lower, upper, 0.0 if restitution is None else restitution)
        if restitution is not None:
            raise ParameterError("joint_limits takes restitution (hard) or stiffness and "
                                 "damping (compliant), not both")
        return CompliantLimits(lower, upper, stiffness, 0.0 if damping is None else damping)

    def constants(self, arm) -> dict:
        return {"LOWER1": self.lower[0], "LOWER2": self.lower[1],
                "UPPER1": self.upper[0], "UPPER2": self.upper[1]}

    def inside(self, q) -> str:
        """'' if every angle of q is within the limits, else which one is not."""
        for i, (v, lo, hi) in enumerate(zip(q, self.lower, self.upper)):
            if not lo <= v <= hi:
                return f"joint {i + 1} at {v:g} rad is outside its limits [{lo:g}, {hi:g}]"
        return ""


class HardLimits(JointLimits):
    def __init__(self, lower, upper, restitution=0.0):
        super().__init__(lower, upper)
        if not 0.0 <= restitution <= 1.0:
            raise ParameterError(f"joint_limits.restitution = {restitution:g} is impossible: "
                                 "it must be in [0, 1]")
        self.restitution = float(restitution)

    def channels(self):
        return (Channel("impact_loss", "0.0", "loss"),)   # booked at each impact (events.py)

    def guards(self, mode) -> list[tuple[str, str, int]]:
        out = []
        for i, code in enumerate(mode[:2]):
            j = i + 1
            if code == "lower":
                out.append((f"lam{j}", "release", i))
            elif code == "upper":
                out.append((f"-lam{j}", "release", i))
            elif code != "stuck":
                out += [(f"UPPER{j} - q{j}", "impact", i), (f"q{j} - LOWER{j}", "impact", i)]
        return out


class CompliantLimits(JointLimits):
    hard = False

    def __init__(self, lower, upper, stiffness, damping=0.0):
        super().__init__(lower, upper)
        self.spring, self.damper = float(stiffness), float(damping)

    def constants(self, arm) -> dict:
        return super().constants(arm) | {"LK": self.spring, "LC": self.damper}

    def forces(self) -> list[str]:
        """Mode-free form (beyond read from the stage's angles): the torque read-out only."""
        lines = []
        for j in (1, 2):
            lines += [f"dl{j} = MAX(q{j} - UPPER{j}, 0.0) + MIN(q{j} - LOWER{j}, 0.0)",
                      f"f{j} -= LK * dl{j} + LC * u{j} * (dl{j} != 0.0)"]
        return lines + ["pl = LC * (u1 * u1 * (dl1 != 0.0) + u2 * u2 * (dl2 != 0.0))"]

    def mode_forces(self, mode) -> list[str]:
        lines, power = [], []
        for i, zone in enumerate(mode[2:4]):
            j = i + 1
            if zone:
                bound = "UPPER" if zone > 0 else "LOWER"
                lines += [f"dl{j} = q{j} - {bound}{j}", f"f{j} -= LK * dl{j} + LC * u{j}"]
                power.append(f"u{j} * u{j}")
        return lines + [f"pl = LC * ({' + '.join(power)})" if power else "pl = 0.0"]

    def channels(self):
        return (Channel("dissipated", "pl", "loss"),) if self.damper else ()

    def guards(self, mode) -> list[tuple[str, str, int]]:
        out = []
        for i, zone in enumerate(mode[2:4]):
            j = i + 1
            if zone > 0:
                out.append((f"q{j} - UPPER{j}", "leave", i))
            elif zone < 0:
                out.append((f"LOWER{j} - q{j}", "leave", i))
            else:
                out += [(f"UPPER{j} - q{j}", "enter", i), (f"q{j} - LOWER{j}", "enter", i)]
        return out

    def stored_energy(self, arm, q, extra) -> float:
        total = 0.0
        for v, lo, hi in zip(q, self.lower, self.upper):
            over, under = v - hi, v - lo                 # array-safe: no max/min/if
            over, under = 0.5 * (over + abs(over)), 0.5 * (under - abs(under))
            total = total + over * over + under * under
        return 0.5 * self.spring * total

    def engaged_stiffness(self, arm) -> float:
        """Decay rate the damper adds while a joint is beyond its limit (1/s)."""
        return self.damper * worst_stiffness(arm)

    def engaged_frequency(self, arm) -> float:
        """Angular frequency the stiffness adds while a joint is beyond (rad/s)."""
        return sqrt(self.spring * worst_stiffness(arm))
