"""The right-hand side f(s), assembled from exactly the effects a scene calls for.

The rigid-body part (mass matrix, velocity-product torques, the LDLᵀ solve) is always
there; each effect (effects/) adds its lines in between, so a scene without gravity never
evaluates a gravity term (not even multiplied by zero) and a scene without damping has no
dissipation channel. The formulas are those of `model` written out once more as
straight-line code, because a function call per term would cost more than the physics on a
2-DOF arm; test_dynamics checks the two agree.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from math import cos, sin

from . import model
from .effects import Channel, Effect, scene_effects
from .sensing import drives
from .stepping.generated import source_code

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
    "    a2 = (f2 - l21 * f1) / (M22 - l21 * m12)",
    "    a1 = f1 / m11 - l21 * a2",
]
# A fixed joint (stuck, resting on a hard limit) is a constraint: its acceleration is exactly
# 0, the other joint moves with the reduced dynamics, and lamᵢ is the torque that holds it.
CONSTRAINED_SOLVE = {
    (False, False): SOLVE + ["    lam1 = 0.0; lam2 = 0.0"],
    (True, False): ["    a1 = 0.0", "    a2 = f2 / M22", "    lam1 = m12 * a2 - f1", "    lam2 = 0.0"],
    (False, True): ["    a2 = 0.0", "    a1 = f1 / m11", "    lam2 = m12 * a1 - f2", "    lam1 = 0.0"],
    (True, True): ["    a1 = 0.0; a2 = 0.0", "    lam1 = -f1; lam2 = -f2"],
}
FIXED = ("stuck", "lower", "upper")
# How the accelerations answer a unit torque on each joint (g11, g12 = g21, g22): M⁻¹ as
# SOLVE computes it, or the constrained mode's (a fixed joint answers none).
RESPONSE = {
    (False, False): ["    c = cos(q2)", "    m11 = A + TWO_B * c", "    m12 = D + B * c",
                     "    l21 = m12 / m11", "    g22 = 1.0 / (M22 - l21 * m12)",
                     "    g12 = -l21 * g22", "    g11 = 1.0 / m11 - l21 * g12"],
    (True, False): ["    g11 = 0.0; g12 = 0.0; g22 = 1.0 / M22"],
    (False, True): ["    g11 = 1.0 / (A + TWO_B * cos(q2)); g12 = 0.0; g22 = 0.0"],
    (True, True): ["    g11 = 0.0; g12 = 0.0; g22 = 0.0"],
}


@dataclass
class Dynamics:
    """f(q1, q2, qd1, qd2, *extra) -> (qdd1, qdd2, *extra rates, *channel rates), plus what
    it was built from."""

    function: object
    source: str
    active: tuple[Effect, ...]        # the effects, in assembly order
    extra: tuple[str, ...]            # names of the effects' extra states (i1, i2 ...)
    channels: tuple[str, ...]         # channel names, in state order
    channel_kinds: tuple[str, ...]    # "input", "loss" or "transfer", per channel
    arm: model.ArmParameters
    torque_function: object           # the same lines up to the joint torque: (t1, t2)
    command: list = field(default_factory=lambda: [0.0, 0.0])   # the torque the code reads
    decay: tuple = ()                 # the extra states' linear decay rates (R/L), 1/s
    given: list | None = None         # where commands are given: `command` itself, or under a
                                      # control loop (sensing/loop.py) the loop's input

    def __post_init__(self):
        self.given = self.command if self.given is None else self.given

    @property
    def effects(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.active)

    def joint_torque(self, state):
        """(tau1, tau2) the joints receive at `state` (after effort limits and windings)."""
        return self.torque_function(*state[:4 + len(self.extra)])

    def driver_check(self):
        """q-state -> '' or what a motor driver with a voltage limit was asked beyond it, for
        the policy's torque (after effort limits) at that state; None without such a driver."""
        effects = {e.name: e for e in self.active}
        motors, limits = effects.get("motors"), effects.get("effort_limits")
        if motors is None or motors.voltage_limit is None:
            return None

        def check(state):
            if "servo" in effects:            # it clamps to the effort limits itself
                return motors.saturation(effects["servo"].requested_torque(state))
            torque = effects["actuator"].requested_torque(state[0:2])
            return motors.saturation(limits.clamp(torque) if limits is not None else torque)

        return check

    def applied_torque(self, q):
        """(tau1, tau2) the joints receive at configuration q at rest (no extra state)."""
        return self.torque_function(q[0], q[1], 0.0, 0.0, *(0.0,) * len(self.extra))


def assemble(arm: model.ArmParameters, effects, command=None, label: str = "") -> Dynamics:
    """Generate and compile f from the rigid body and `effects`: their stage terms in list
    order, then their forces, inputs first (f = τ − c − g − D q̇ …)."""
    a, b, d, m22 = arm.mass_constants
    namespace = {"cos": cos, "sin": sin, "MIN": min, "MAX": max,
                 "A": a, "B": b, "TWO_B": 2.0 * b, "D": d, "M22": m22}
    for effect in effects:
        namespace.update(effect.constants(arm))
    extra = [name for effect in effects for name in effect.state]
    signature = ", ".join(["q1", "q2", "u1", "u2"] + extra)
    terms = stage_terms(effects)
    lines = [f"def rhs({signature}):"] + body(effects)
    channels = merged_channels(effects)
    lines += SOLVE + ["    return " + ", ".join(["a1", "a2"] + rates(effects)
                                                 + [c.rate for c in channels])]
    drives = any(effect.drives for effect in effects)
    torque = ([f"def torque({signature}):"] + terms + ["    return t1, t2"] if drives else
              [f"def torque({signature}):", "    return 0.0, 0.0"])
    source = "\n".join(lines) + "\n" + response_source(effects)
    names = "+".join(e.name for e in effects) or "free"
    exec(source_code(source, f"<rhs {label}, {names}>"), namespace)
    exec(source_code("\n".join(torque) + "\n", f"<joint torque {label}, {names}>"), namespace)
    return Dynamics(namespace["rhs"], source, tuple(effects), tuple(extra),
                    tuple(c.name for c in channels), tuple(c.kind for c in channels), arm,
                    namespace["torque"], command if command is not None else [0.0, 0.0],
                    tuple(rate for effect in effects for rate in effect.linear_decay()))


def response_source(effects, fixed=(False, False)) -> str:
    """response(q1, q2): each extra state's pull on the accelerations, (d a1/dx, d a2/dx) per
    state, where it scales a joint torque (a winding's current: Effect.state_torques), 0
    elsewhere, set as the attribute `response` of the rhs defined before it (whoever runs
    the source: a mode's, a Batch's arrays); "" without such a state. The exponential step
    integrates it exactly with the currents (stepping/exponential.py); in a mode a fixed
    joint answers none."""
    torques = [t for effect in effects for t in effect.state_torques()]
    if not any(torques):
        return ""
    pairs = [(f"{t[0]} * g11", f"{t[0]} * g12") if t and t[1] == 0 else
             (f"{t[0]} * g12", f"{t[0]} * g22") if t else ("0.0", "0.0") for t in torques]
    return "\n".join(["def response(q1, q2):", *RESPONSE[fixed],
                      f"    return {', '.join(v for pair in pairs for v in pair)},",
                      "rhs.response = response   # the rhs it answers for carries it"]) + "\n"


def body(effects, mode=None) -> list[str]:
    """The rigid body, the effects' stage terms, then their forces, inputs first; switching
    effects in `mode` (None: their mode-free form)."""
    lines = RIGID_BODY + stage_terms(effects, mode)
    for effect in sorted(effects, key=lambda e: not e.drives):
        forces = effect.mode_forces(mode) if mode is not None else effect.forces()
        lines += ["    " + line for line in forces]
    return lines


def stage_terms(effects, mode=None) -> list[str]:
    """The effects' stage lines (a switching clamp's in `mode`; None: the mode-free form)."""
    return ["    " + line for effect in effects
            for line in (effect.mode_terms(mode) if mode is not None else effect.terms())]


def rates(effects) -> list[str]:
    """The effects' rate expressions of their extra states, in state order."""
    return [r for effect in effects for r in effect.rates()]


def merged_channels(effects) -> list[Channel]:
    """The effects' channels; two of one name (damping's and a compliant limit's
    `dissipated`) become one whose rate is the sum."""
    merged = {}
    for channel in (c for effect in effects for c in effect.channels()):
        if channel.name in merged:
            channel = Channel(channel.name, f"{merged[channel.name].rate} + {channel.rate}",
                              channel.kind)
        merged[channel.name] = channel
    return list(merged.values())


def mode_functions(dynamics: Dynamics, mode, guards, requests=()):
    """(rhs, probe, guard, requests) of `mode`: rhs as Dynamics.function, with the fixed
    joints' accelerations exactly 0; probe(q1, q2, u1, u2, *extra) -> (lam1, lam2, *guards),
    the holding torques and the switching functions (expressions) there; guard -> the
    latter; requests -> the expressions `requests` (the clamps' requests; None without)."""
    fixed = tuple(code in FIXED for code in mode[:2])
    signature = ", ".join(["q1", "q2", "u1", "u2"] + list(dynamics.extra))
    lines = body(dynamics.active, mode) + CONSTRAINED_SOLVE[fixed]
    channels = [c.rate for c in merged_channels(dynamics.active)]
    returned = ["a1", "a2"] + rates(dynamics.active) + channels
    rhs = "\n".join([f"def rhs({signature}):"] + lines + ["    return " + ", ".join(returned)])
    if response_source(dynamics.active, fixed):      # the exponential step's (windings)
        rhs += "\n" + response_source(dynamics.active, fixed)
    source = "\n".join([rhs, f"def probe({signature}):"] + lines
                       + ["    return " + ", ".join(["lam1", "lam2"] + list(guards)) + ","]) + "\n"
    terms = stage_terms(dynamics.active, mode)
    values = f"({', '.join(guards)},)" if guards else "()"
    assigned = set(re.findall(r"(\w+)\s*=(?!=)", "\n".join(terms)))
    used = set(re.findall(r"[A-Za-z_]\w*", " ".join(guards)))
    if any("lam" in g for g in guards):          # the holding torques: the whole solve
        source += f"def guard({signature}):\n    return probe({signature})[2:]\n"
    elif used & assigned:                        # a clamp's request: the stage terms alone
        source += "\n".join([f"def guard({signature}):"] + terms
                             + [f"    return {values}"]) + "\n"
    else:                                        # the switching functions alone: cheap
        source += f"def guard({signature}):\n    return {values}\n"
    guards_source = source[len(rhs) + 1:]       # probe and guard: compiled.py compiles them
    if requests:
        source += "\n".join([f"def requests({signature}):"] + terms
                             + [f"    return ({', '.join(requests)},)"]) + "\n"
    namespace = dict(dynamics.function.__globals__)
    exec(source_code(source, f"<rhs in mode {mode}>"), namespace)
    namespace["rhs"].source = rhs + "\n"       # compiled.py compiles it with the step
    namespace["rhs"].guards_source = guards_source if guards else ""
    return namespace["rhs"], namespace["probe"], namespace["guard"], namespace.get("requests")


def build_dynamics(scene, command=None) -> Dynamics:
    """The dynamics of a scene: exactly the effects it names (effects/scene_effects); under a
    control loop the drive reads the loop's torque, and `command` is the loop's input."""
    command = [0.0, 0.0] if command is None else command
    acting = [0.0, 0.0] if drives(scene) else None
    dynamics = assemble(scene.arm, scene_effects(scene, command, acting),
                        command if acting is None else acting, label=scene.policy)
    dynamics.given = command
    return dynamics


def book_entries(dynamics) -> tuple[list, list]:
    """Where in the state the input channels are, and the loss channels."""
    first = 4 + len(dynamics.extra)
    return tuple([first + i for i, each in enumerate(dynamics.channel_kinds) if each == kind]
                 for kind in ("input", "loss"))
