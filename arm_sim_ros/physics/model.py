"""Planar two-revolute arm: mass matrix, velocity-product and gravity torques, energy.

Conventions (the explainer's): q1 from world +x counter-clockwise, q2 relative to
link 1, y up, gravity along -y, positive torque counter-clockwise, V = 0 with both
links horizontal. Plain floats: a 2-DOF arm is far cheaper without numpy.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from math import cos, isfinite, pi, sin

PAIR_FIELDS = ("link_lengths", "link_masses", "com_distances", "com_inertias")
MAX_ANGLE = 1e6   # rad: beyond it sin and cos keep no digit of an angle; nothing physical goes there


class ParameterError(ValueError):
    """A physical parameter set that cannot describe a real arm."""


class StepRefused(ValueError):
    """A step refused for a physical reason its message gives (too stiff for the plan)."""


def arithmetic_fault(error: ArithmeticError | ValueError) -> str:
    """What an arithmetic error in a step means for the arm, in its words rather than
    Python's ("math domain error", "float division by zero", "math range error")."""
    if isinstance(error, StepRefused):
        return str(error)
    if isinstance(error, ZeroDivisionError):
        return "a quantity divided by one that vanished (a singular mass matrix or a zero rate)"
    if isinstance(error, OverflowError):
        return "a velocity, torque or energy beyond double precision (1.8e308)"
    return "an angle or velocity beyond what sin, cos and sqrt can take (the state left the doubles)"


BRIEF = 200   # characters of a refused value a message shows


def brief(value, limit: int = BRIEF) -> str:
    """repr(value) for a message: at most `limit` characters and its length, so a 100 KB
    value makes a short line; an integer too long to print is named by its digits."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 1000:
        return f"an integer of about {int(value.bit_length() * 0.30103) + 1} digits"
    try:
        text = repr(value)
    except ValueError:                   # a container holding an integer too long to print
        return f"a {type(value).__name__} holding an integer too long to print"
    return text if len(text) <= limit else f"{text[:limit]}… ({len(text)} chars)"


@dataclass(frozen=True)
class ArmParameters:
    """Link i: length l_i, mass m_i, centre of mass r_i from its joint, inertia I_i about the COM.

    Defaults are the explainer's uniform rods: 1 m, 1 kg, COM at 0.5 m, I = 1/12 kg m^2.
    """

    link_lengths: tuple[float, float] = (1.0, 1.0)
    link_masses: tuple[float, float] = (1.0, 1.0)
    com_distances: tuple[float, float] = (0.5, 0.5)
    com_inertias: tuple[float, float] = (1.0 / 12.0, 1.0 / 12.0)
    armature: tuple[float, float] = (0.0, 0.0)    # reflected rotor inertia added to M11, M22

    def __post_init__(self):
        for name in PAIR_FIELDS + ("armature",):
            value = tuple(float(v) for v in getattr(self, name))
            if len(value) != 2:
                raise ParameterError(f"{name} needs two values (one per link), got {len(value)}")
            if not all(isfinite(v) for v in value):
                raise ParameterError(f"{name} must be finite, got {list(value)}")
            object.__setattr__(self, name, value)
        for name, test, what in (
            ("link_lengths", lambda v: v > 0, "positive"),
            ("link_masses", lambda v: v > 0, "positive"),
            ("com_inertias", lambda v: v >= 0, "non-negative"),
            ("armature", lambda v: v >= 0, "non-negative"),
        ):
            for i, v in enumerate(getattr(self, name)):
                if not test(v):
                    raise ParameterError(f"{name}[{i}] = {v} is impossible: it must be {what}")
        # det M(q2) is smallest at full extension or fold (cos q2 = +-1); a set whose
        # determinant vanishes there has a singular mass matrix and cannot be simulated.
        a, b, d, m22 = self.mass_constants
        det_min = a * m22 - d * d - b * b
        if not all(isfinite(v) for v in (a, b, d, m22, det_min, a * m22)):
            raise ParameterError(
                "the arm's masses, lengths and inertias are so large that its mass matrix "
                f"overflows double precision (M11 = {a:.3g}); use SI units at a robot's scale")
        if not det_min > 1e-12 * a * m22:
            raise ParameterError(
                "the mass matrix becomes singular at some elbow angle "
                f"(min det M = {det_min:.3g}); link 2 needs mass away from the elbow axis or inertia")

    @property
    def inertia_coefficients(self) -> tuple[float, float, float]:
        """(a, b, d) with M11 = a + 2b cos q2, M12 = d + b cos q2, M22 = d."""
        (l1, _), (m1, m2), (r1, r2), (i1, i2) = (
            self.link_lengths, self.link_masses, self.com_distances, self.com_inertias)
        d = i2 + m2 * r2 * r2
        a = i1 + m1 * r1 * r1 + m2 * l1 * l1 + d
        b = m2 * l1 * r2
        return a, b, d

    @property
    def mass_constants(self) -> tuple[float, float, float, float]:
        """(A, b, d, M22): M11 = A + 2b cos q2, M12 = d + b cos q2, M22, armature included."""
        a, b, d = self.inertia_coefficients
        return a + self.armature[0], b, d, d + self.armature[1]

    def with_payload(self, mass: float) -> "ArmParameters":
        """The arm with a point mass at the tip of link 2, folded into link 2 exactly: the
        combined mass, its centre of mass and its inertia about that centre."""
        if mass == 0.0:
            return self
        try:
            folded = fold_payload(self.link_lengths[1], self.link_masses[1],
                                  self.com_distances[1], self.com_inertias[1], mass)
        except OverflowError:      # a square past the doubles raises, a product gives inf
            folded = (float("inf"),) * 3
        if not all(isfinite(v) for v in folded):
            raise ParameterError(f"a payload of {mass:g} kg at the tip of link 2 "
                                 f"({self.link_lengths[1]:g} m, {self.link_masses[1]:g} kg) "
                                 "gives a mass, centre of mass or inertia beyond double "
                                 "precision; use values at a robot's scale")
        total, com, inertia = folded
        return replace(self, link_masses=(self.link_masses[0], total),
                       com_distances=(self.com_distances[0], com),
                       com_inertias=(self.com_inertias[0], inertia))

    @property
    def gravity_coefficients(self) -> tuple[float, float]:
        """(k1, k2) with V = gravity (k1 sin q1 + k2 sin(q1 + q2))."""
        (l1, _), (m1, m2), (r1, r2) = self.link_lengths, self.link_masses, self.com_distances
        return m1 * r1 + m2 * l1, m2 * r2


def angle_warning(initial_positions, node: bool = False) -> str | None:
    """A sentence when an initial angle is beyond one turn: likely degrees given as radians."""
    beyond = [q for q in initial_positions if abs(q) > 2 * pi]
    if not beyond:
        return None
    if node:   # a ROS 2 list holds one type: deg on every number
        meant = '-p "initial_positions:=[' + ", ".join(
            f"{q:g}deg" for q in initial_positions) + ']"'

    else:
        meant = "initial_positions=" + ",".join(f"{q:g}deg" for q in initial_positions)
    return (f"initial_positions {list(initial_positions)} rad: {beyond[0]:g} rad is more "
            f"than a full turn (2π = 6.283 rad); angles are radians. If you meant degrees, "
            f"write {meant}")


def fold_payload(length, mass, com, inertia, payload):
    """Link 2 with a point mass `payload` at its tip: (mass, centre of mass, inertia about
    it). Plain arithmetic, so it also folds per-arm arrays (Batch)."""
    total = mass + payload
    combined = (mass * com + payload * length) / total
    return (total, combined,
            inertia + mass * (com - combined) ** 2 + payload * (length - combined) ** 2)


def mass_matrix(arm: ArmParameters, q):
    """(M11, M12, M22) of the symmetric joint-space mass matrix."""
    a, b, d, m22 = arm.mass_constants
    c2 = cos(q[1])
    return a + 2.0 * b * c2, d + b * c2, m22


def velocity_torque(arm: ArmParameters, q, qd):
    """c(q, qd): the Coriolis and centrifugal torques."""
    _, b, _ = arm.inertia_coefficients
    h = b * sin(q[1])
    return -h * (2.0 * qd[0] * qd[1] + qd[1] * qd[1]), h * qd[0] * qd[0]


def gravity_torque(arm: ArmParameters, q, gravity: float):
    """g(q) = dV/dq for gravity magnitude `gravity` along -y."""
    k1, k2 = arm.gravity_coefficients
    g2 = gravity * k2 * cos(q[0] + q[1])
    return gravity * k1 * cos(q[0]) + g2, g2


def kinetic_energy(arm: ArmParameters, q, qd) -> float:
    m11, m12, m22 = mass_matrix(arm, q)
    return 0.5 * (m11 * qd[0] * qd[0] + 2.0 * m12 * qd[0] * qd[1] + m22 * qd[1] * qd[1])


def potential_energy(arm: ArmParameters, q, gravity: float) -> float:
    k1, k2 = arm.gravity_coefficients
    return gravity * (k1 * sin(q[0]) + k2 * sin(q[0] + q[1]))


def solve_mass_matrix(m11: float, m12: float, m22: float, f1: float, f2: float):
    """Solve M x = f by the LDL^T (square-root-free Cholesky) factors of the SPD matrix."""
    l21 = m12 / m11
    x2 = (f2 - l21 * f1) / (m22 - l21 * m12)
    return f1 / m11 - l21 * x2, x2


def forward_dynamics(arm: ArmParameters, q, qd, torque=(0.0, 0.0), gravity: float = 0.0,
                     damping: float = 0.0):
    """qdd from M(q) qdd = tau - c(q, qd) - g(q) - d qd."""
    c1, c2 = velocity_torque(arm, q, qd)
    g1, g2 = gravity_torque(arm, q, gravity)
    f1 = torque[0] - c1 - g1 - damping * qd[0]
    f2 = torque[1] - c2 - g2 - damping * qd[1]
    return solve_mass_matrix(*mass_matrix(arm, q), f1, f2)


def inverse_dynamics(arm: ArmParameters, q, qd, qdd, gravity: float = 0.0, damping: float = 0.0):
    """tau = M(q) qdd + c(q, qd) + g(q) + d qd."""
    m11, m12, m22 = mass_matrix(arm, q)
    c1, c2 = velocity_torque(arm, q, qd)
    g1, g2 = gravity_torque(arm, q, gravity)
    return (m11 * qdd[0] + m12 * qdd[1] + c1 + g1 + damping * qd[0],
            m12 * qdd[0] + m22 * qdd[1] + c2 + g2 + damping * qd[1])


def link_points(arm: ArmParameters, q):
    """Base, elbow and tip positions (x, y), y up."""
    l1, l2 = arm.link_lengths
    ex, ey = l1 * cos(q[0]), l1 * sin(q[0])
    return (0.0, 0.0), (ex, ey), (ex + l2 * cos(q[0] + q[1]), ey + l2 * sin(q[0] + q[1]))
