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
from math import isfinite

from ...usage import did_you_mean
from ..model import ParameterError, brief

REQUIRED = object()
CHECKS = {  # check name: (test, what the value must be)
    "any": (lambda v: True, "finite"),
    "positive": (lambda v: v > 0, "positive"),
    "non-negative": (lambda v: v >= 0, "non-negative"),
    "whole": (lambda v: 0 <= v < 2 ** 63 and v % 1 == 0, "a whole number from 0 to 2^63 - 1"),
}


def must_be(check: str, limit: float | None) -> str:
    """What a value under `check` and `limit` must be, in words (messages, the reference)."""
    what = CHECKS[check][1]
    return what if limit is None else f"{what}, at most {limit:g} in magnitude"


@dataclass(frozen=True)
class Parameter:
    """One scene key of an effect: `<effect>.<name>` in a scene file, --set and ROS params."""

    name: str
    kind: str              # "pair" (one value per joint), "float", "int" (a whole number,
    unit: str              # held exactly), "names" (one of `choices` per joint) or "choice"
    check: str = "any"     # (one of `choices`)
    default: object = REQUIRED
    description: str = ""
    choices: tuple = ()
    limit: float | None = None   # the largest magnitude (an angle's: model.MAX_ANGLE)

    def coerce(self, effect: str, value):
        """The value as a float, an int or a pair of floats, or ParameterError saying why."""
        label = effect if effect == self.name else f"{effect}.{self.name}"   # effort_limits
        if self.kind == "names":
            return self._names(label, value)
        if self.kind == "choice":
            value = "true" if value is True else value       # YAML reads `true` as a bool
            if not isinstance(value, str) or value not in self.choices:
                raise ParameterError(f"{label} = {brief(value)} is not one of "
                                     f"{', '.join(self.choices)}")
            return value
        if self.kind == "pair":
            if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
                raise ParameterError(f"{label} must be a list of two numbers ({self.unit}), "
                                     f"got {brief(value)}")
            if len(value) != 2:
                raise ParameterError(f"{label} needs two numbers, one per joint ({self.unit}), "
                                     f"got {len(value)}")
            return tuple(self._number(f"{label}[{i}]", v) for i, v in enumerate(value))
        if self.kind == "int":
            value = whole_number(label, value, self.unit)
            test, what = CHECKS[self.check]
            if not test(value):
                raise ParameterError(f"{label} = {brief(value, 40)} is impossible: it must be "
                                     f"{what}{in_unit(self.unit)}")
            return value
        return self._number(label, value)

    def _names(self, label: str, value) -> tuple:
        if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
            raise ParameterError(f"{label} needs two names, one per joint ({self.unit}), "
                                 f"got {value!r}")
        for i, name in enumerate(value):
            if name not in self.choices:
                raise ParameterError(f"{label}[{i}] = {name!r} is not one of "
                                     f"{', '.join(self.choices)}")
        return tuple(value)

    def _number(self, label: str, value) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(f"{label} must be a number ({self.unit}), got {brief(value)}")
        try:
            value = float(value)
        except OverflowError:
            value = float("inf")
        test, _ = CHECKS[self.check]
        if not isfinite(value) or not test(value) or (self.limit is not None
                                                      and abs(value) > self.limit):
            raise ParameterError(f"{label} = {value:g} is impossible: it must be "
                                 f"{must_be(self.check, self.limit)} ({self.unit})")
        return value


def whole_number(label: str, value, unit: str) -> int:
    """An integer key (a seed, max_substeps) as an int, from an int or a whole double; a
    double holds whole numbers exactly only up to 2^53, so one beyond it is refused rather
    than taken for a neighbour (2^60 and 2^60 + 1 read alike as doubles)."""
    if isinstance(value, float) and value.is_integer() and abs(value) <= 2 ** 53:
        return int(value)            # 7.0 from a YAML or a double parameter: 7
    if isinstance(value, float) and value.is_integer():
        raise ParameterError(f"{label} = {value:g} was read as a double, which holds whole "
                             "numbers exactly only up to 2^53: write it as an integer, "
                             "without a decimal point or an exponent")
    if isinstance(value, float):
        raise ParameterError(f"{label} = {value:g} is impossible: it must be a whole "
                             f"number{in_unit(unit)}")
    if isinstance(value, bool) or not isinstance(value, int):
        raise ParameterError(f"{label} must be a whole number{in_unit(unit)}, got "
                             f"{brief(value)}")
    return value


def in_unit(unit: str) -> str:
    """` (unit)` for a message, nothing for a pure number (unit "1")."""
    return "" if unit == "1" else f" ({unit})"


def validate(effect: str, parameters, mapping) -> dict:
    """An effect's scene mapping checked against its parameters; defaults filled in."""
    if not isinstance(mapping, dict):
        raise ParameterError(f"{effect} must be a mapping of "
                             f"{', '.join(p.name for p in parameters)}, got {brief(mapping)}")
    known = {p.name: p for p in parameters}
    unknown = sorted(set(map(str, mapping)) - set(known))
    if unknown:
        hint = did_you_mean(f"{effect}.{unknown[0]}", [f"{effect}.{k}" for k in known])
        raise ParameterError(f"{effect}.{unknown[0]} is not a key of {effect}; {hint}its keys: "
                             f"{', '.join(known)}")
    values = {}
    for name, parameter in known.items():
        if name in mapping and mapping[name] is not None:
            values[name] = parameter.coerce(effect, mapping[name])
        elif parameter.default is REQUIRED:
            raise ParameterError(f"{effect} needs {effect}.{name} ({parameter.unit})")
        elif parameter.default is not None:
            values[name] = parameter.default
    return values


def clamp_lines(request: str, target: str, limit: str, clamp: int) -> list[str]:
    """`target` = `request` (clamp 0) or ±`limit` (clamp 1/-1)."""
    return [f"{target} = {request if not clamp else ('' if clamp > 0 else '-') + limit}"]


def clamp_guards(request: str, limit: str, clamp: int, kind: str, joint: int) -> list:
    """(g, kind, joint): the clamp's mode holds while g >= 0 (passing: within ±limit;
    holding +limit: request >= limit; holding -limit: request <= -limit)."""
    if clamp == 0:
        return [(f"{limit} - {request}", kind, joint), (f"{request} + {limit}", kind, joint)]
    if clamp > 0:
        return [(f"{request} - {limit}", kind, joint)]
    return [(f"-{limit} - {request}", kind, joint)]


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
    switching = False  # non-smooth: its force depends on a mode that events.py switches
    state = ()         # names of the extra states it adds (winding currents), initially 0

    def constants(self, arm) -> dict:
        """Names the generated code reads; values may be per-arm arrays (Batch)."""
        return {}

    def terms(self) -> list[str]:
        """Lines computing the stage's quantities (gravity's g1, g2, the actuator's t1, t2)."""
        return []

    def forces(self) -> list[str]:
        """Lines adding this effect's generalized force to f1, f2."""
        return []

    def mode_terms(self, mode) -> list[str]:
        """A switching clamp's stage lines in `mode`, whose fifth entry holds the clamps'
        modes (effort 1, effort 2, voltage 1, voltage 2: 0 passes, 1/-1 holds +/-limit)."""
        return self.terms()

    def mode_forces(self, mode) -> list[str]:
        """A switching effect's force lines in `mode` = (code1, code2, zone1, zone2), smooth
        within it: code "+"/"-" sliding, "stuck", "lower"/"upper" resting on a hard limit
        (those three fix the joint), "free"; zone 1/-1 beyond a compliant limit, else 0."""
        return self.forces()

    def guards(self, mode) -> list[tuple[str, str, int]]:
        """Switching functions (expression, event kind, joint): `mode` holds while each
        expression (of q1, q2, u1, u2, the holding torques lam1, lam2 and the names the
        stage terms assign, such as a clamp's request) is >= 0."""
        return []

    def channels(self) -> tuple[Channel, ...]:
        return ()

    def rates(self) -> list[str]:
        """Expressions of d/dt of its extra states, in `state` order."""
        return []

    def linear_decay(self) -> tuple:
        """Linear decay rates (1/s) of its extra states, integrated exactly where the method
        allows (integrators.compile_exponential_step): x' = -rate x + the rest."""
        return (0.0,) * len(self.state)

    def stored_energy(self, arm, q, extra) -> float:
        """Energy it stores at configuration q and its extra states, counted in E."""
        return 0.0

    def lowest_stored_energy(self, arm) -> float:
        """A lower bound of stored_energy over every state (0: it stores none or >= 0):
        energy above it can be set in motion, wherever the effect puts its zero."""
        return 0.0

    def stiffness(self, arm) -> float:
        """The largest decay rate (1/s) it adds on the negative real axis, at any pose: what
        the sub-step planner keeps h times under the integrator's stability limit."""
        return 0.0

    def frequency(self, arm) -> float:
        """The largest angular frequency (rad/s) of the oscillation it adds, at any pose
        (springs); nonzero makes the planner use the stability region's half-disk."""
        return 0.0
