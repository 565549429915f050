"""The right-hand side f(s), assembled from exactly the effects a scene calls for.

Each effect contributes lines of source to one generated function; an absent effect
contributes none, so a scene without gravity never evaluates a gravity term (not even
multiplied by zero) and a scene without damping has no dissipation channel. The
formulas are those of `model` written out once more as straight-line code, because a
function call per term would cost more than the physics on a 2-DOF arm;
test_dynamics checks the two agree.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from math import cos, sin

from . import model

POLICIES = ("zero", "constant", "gravity_compensation", "frozen_gravity", "command",
            "command_gravity_compensation")
POLICY_TORQUE = {
    # policy: (torque lines, needs the gravity torque g of the current stage)
    "constant": ("t1 = TORQUE1; t2 = TORQUE2", False),
    "frozen_gravity": ("t1 = TORQUE1; t2 = TORQUE2", False),
    "gravity_compensation": ("t1 = g1; t2 = g2", True),
    "command": ("t1 = command[0]; t2 = command[1]", False),
    "command_gravity_compensation": ("t1 = command[0] + g1; t2 = command[1] + g2", True),
}


@dataclass
class Dynamics:
    """f(q1, q2, qd1, qd2) -> (qdd1, qdd2, *channel rates), plus what it was built from."""

    function: object
    source: str
    effects: tuple[str, ...]          # subset of ("gravity", "damping", "actuator")
    channels: tuple[str, ...]         # subset of ("work", "dissipated"), in state order
    applied_torque: object            # q -> (tau1, tau2) as the policy applies it now
    command: list = field(default_factory=lambda: [0.0, 0.0])


def build_dynamics(arm: model.ArmParameters, gravity: float, damping: float, policy: str,
                   constant_torque=(0.0, 0.0), initial_positions=(0.0, 0.0)) -> Dynamics:
    if policy not in POLICIES:
        raise ValueError(f"unknown policy {policy!r}; choose one of {', '.join(POLICIES)}")
    a, b, d = arm.inertia_coefficients
    k1, k2 = arm.gravity_coefficients
    command = [0.0, 0.0]
    namespace = {"cos": cos, "sin": sin, "A": a, "B": b, "TWO_B": 2.0 * b, "D": d,
                 "G1": gravity * k1, "G2": gravity * k2, "DAMPING": damping, "command": command}

    has_gravity = gravity != 0.0
    actuator = POLICY_TORQUE.get(policy)
    if policy == "constant":
        fixed = tuple(constant_torque)
    elif policy == "frozen_gravity":
        fixed = model.gravity_torque(arm, initial_positions, gravity)
    else:
        fixed = None
    if fixed is not None:
        namespace["TORQUE1"], namespace["TORQUE2"] = fixed
    if actuator is not None and actuator[1] and not has_gravity:
        # Compensating absent gravity is no torque at all.
        actuator = None if policy == "gravity_compensation" else (POLICY_TORQUE["command"][0], False)

    lines = [
        "def rhs(q1, q2, u1, u2):",
        "    c = cos(q2)",
        "    m11 = A + TWO_B * c",
        "    m12 = D + B * c",
        "    h = B * sin(q2)",
        "    f1 = h * (2.0 * u1 * u2 + u2 * u2)",   # -c(q, qd)
        "    f2 = -h * u1 * u1",
    ]
    effects, rates, channels = [], [], []
    if has_gravity:
        effects.append("gravity")
        lines += ["    g2 = G2 * cos(q1 + q2)",
                  "    g1 = G1 * cos(q1) + g2"]
    if actuator is not None:
        effects.append("actuator")
        lines += [f"    {actuator[0]}",
                  "    f1 += t1",
                  "    f2 += t2"]
        rates.append("t1 * u1 + t2 * u2")
        channels.append("work")
    if has_gravity:
        lines += ["    f1 -= g1",
                  "    f2 -= g2"]
    if damping != 0.0:
        effects.append("damping")
        lines += ["    f1 -= DAMPING * u1",
                  "    f2 -= DAMPING * u2"]
        rates.append("DAMPING * (u1 * u1 + u2 * u2)")
        channels.append("dissipated")
    lines += [
        "    l21 = m12 / m11",                      # LDL^T of the SPD mass matrix
        "    a2 = (f2 - l21 * f1) / (D - l21 * m12)",
        "    a1 = f1 / m11 - l21 * a2",
        "    return " + ", ".join(["a1", "a2"] + rates),
    ]
    source = "\n".join(lines) + "\n"
    exec(compile(source, f"<rhs {policy}, {'+'.join(effects) or 'free'}>", "exec"), namespace)

    def applied_torque(q):
        if actuator is None:
            return 0.0, 0.0
        if fixed is not None:
            return fixed
        t1, t2 = command if policy.startswith("command") else (0.0, 0.0)
        if actuator[1]:
            g1, g2 = model.gravity_torque(arm, q, gravity)
            t1, t2 = t1 + g1, t2 + g2
        return t1, t2

    return Dynamics(namespace["rhs"], source, tuple(effects), tuple(channels), applied_torque,
                    command)
