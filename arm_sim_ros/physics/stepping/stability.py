"""Where an explicit Runge-Kutta step stops being stable on this arm, and the sub-steps that fix it.

Joint damping D = d I adds -d M(q)^-1 qd to the accelerations: a real, negative eigenvalue
-d lambda_i for each eigenvalue lambda_i of M^-1. RK4's amplification on the negative real
axis, R(-x) = 1 - x + x^2/2 - x^3/6 + x^4/24, stays within [-1, 1] only while
x <= 2.785, so a step h is stable while d h lambda_max <= 2.785 (15.09 for the explainer's
rods at q2 = 0: d = 18.5 at h = 0.01). Just above it RK4 does not produce NaN at once; it
returns energy-gaining states, which is worse.

Mechanism (chosen by measurement, benchmarks/bench_stiff_damping.py): a step whose
d h Lambda exceeds the limit, Lambda = lambda_max over *every* elbow angle, is taken as the
fewest equal sub-steps with d (h/n) Lambda <= SUBSTEP_FRACTION x limit. Lambda is computed
once per simulator, so the count is constant, no per-step cost is added, and the bound
holds wherever the elbow goes during the step. On 300 random damped states a bound from
the start-of-step elbow angle took 2.5x fewer sub-steps but let a fast elbow swing into a
stiffer pose mid-step and gain 218 J; re-sizing every sub-step from its own angle stayed
passive in those draws, with no guarantee, at 2.4x fewer sub-steps and 100x the error
against Radau; treating damping implicitly (split exact damping flow) was passive but
0.08 rad away from Radau where this is 5e-7.
"""
from __future__ import annotations

from fractions import Fraction
from functools import lru_cache
from math import ceil, cos, hypot, pi, sin

from .integrators import (EXPONENTIAL_RK4, INTEGRATORS, RK4, ButcherTableau, exponential_rk4,
                          integrates_decay_exactly)
from ..model import ArmParameters, StepRefused, mass_matrix

# Sub-steps aim at this fraction of the limit, d h_sub Lambda = 1.0: there R(-1) = 0.375 is
# close to the exact decay e^-1 = 0.368, so a kicked arm's dissipation books stay right
# (d = 50 kicked at 3 rad/s: balance residual 0.015 J; aiming at 2.0, R = 1/3 vs e^-2 = 0.135
# left 0.65 J of 6 J unaccounted, at half the cost; right at the limit R = +1 would not decay).
SUBSTEP_FRACTION = 0.36
# Beyond this a single step would take seconds of CPU (~3 us per sub-step): refused, not run.
MAX_SUBSTEPS = 100_000


def stability_polynomial(tableau: ButcherTableau) -> list[Fraction]:
    """Coefficients of R(z) = 1 + sum_k z^k b^T A^(k-1) 1 for the velocity weights (a, b).

    Damping acts on velocities only, so for partitioned methods (a, b) is what decides it.
    """
    coefficients = [Fraction(1)]
    stage = [Fraction(1)] * tableau.stages          # A^(k-1) 1
    for _ in range(tableau.stages):
        coefficients.append(sum(w * s for w, s in zip(tableau.b, stage)))
        stage = [sum((row[j] * stage[j] for j in range(len(row))), Fraction(0))
                 for row in tableau.a]
    return coefficients


@lru_cache(maxsize=None)   # a tableau's constant; every Simulator build asks
def real_stability_limit(tableau: ButcherTableau) -> float:
    """The largest x with |R(-t)| <= 1 for every t in [0, x] (2.785... for RK4)."""
    coefficients = [float(c) for c in stability_polynomial(tableau)]

    def amplification(t):
        return abs(sum(c * (-t) ** k for k, c in enumerate(coefficients)))

    t, dt = 0.0, 1e-3
    while amplification(t + dt) <= 1.0:
        t += dt
        if t > 1e3:                                  # not an explicit method's polynomial
            return float("inf")
    lo, hi = t, t + dt
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if amplification(mid) <= 1.0 else (lo, mid)
    return lo


@lru_cache(maxsize=None)   # ~0.16 s to compute: once per tableau, not per build
def half_disk_limit(tableau: ButcherTableau) -> float:
    """The largest r with |R(z)| <= 1 on the whole left half-disk |z| <= r (2.61 for RK4):
    where springs and windings put oscillatory eigenvalues, not only real ones."""
    coefficients = [complex(c) for c in stability_polynomial(tableau)]
    angles = [pi / 2 + pi / 2 * k / 90 for k in range(91)]

    def stable(r):
        return all(abs(sum(c * (r * complex(cos(a), sin(a))) ** k
                           for k, c in enumerate(coefficients))) <= 1.0 + 1e-12 for a in angles)

    r, dr = 0.0, 1e-2
    while stable(r + dr):
        r += dr
        if r > 1e3:
            return float("inf")
    lo, hi = r, r + dr
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


RK4_REAL_LIMIT = real_stability_limit(RK4)


def inverse_mass_eigenvalue(m11, m12, m22, hypot=hypot):
    """Largest eigenvalue of M^-1 = 1 / smallest eigenvalue of M, written without
    cancellation; of numpy arrays too, element by element, with hypot=numpy.hypot."""
    half_trace = 0.5 * (m11 + m22)
    spread = hypot(0.5 * (m11 - m22), m12)
    return (half_trace + spread) / (m11 * m22 - m12 * m12)


def stiffness(arm: ArmParameters, q2: float) -> float:
    """lambda_max(M^-1) at elbow angle q2, in 1/(kg m^2)."""
    return inverse_mass_eigenvalue(*mass_matrix(arm, (0.0, q2)))


def worst_stiffness(arm: ArmParameters) -> float:
    """Lambda = max over all elbow angles of lambda_max(M^-1).

    M is affine in cos q2, M^-1 is operator-convex and lambda_max is convex, so the maximum
    over cos q2 in [-1, 1] sits at full extension or full fold.
    """
    return max(stiffness(arm, 0.0), stiffness(arm, pi))


def _exact(exact: bool, effect) -> bool:
    """The effect's extra states decay linearly and the step integrates that exactly."""
    return exact and any(getattr(effect, "linear_decay", tuple)())


def bound(tableau: ButcherTableau, effects, arm: ArmParameters, h: float, exact=None):
    """(ratio, limit, what): h times the effects' largest eigenvalue magnitude at any pose,
    and the tableau's limit for it. Damping alone has real eigenvalues (the real-axis
    limit); springs and windings oscillate, so their bound |lambda| is kept inside the
    half-disk. Windings integrated exactly (exponential RK4) add only their braking here;
    the rest of their coupling is exact_substeps' business."""
    exact = integrates_decay_exactly(tableau) if exact is None else exact
    given = {id(e): {"exact": True} if _exact(exact, e) else {} for e in effects}
    decay = sum(e.stiffness(arm, **given[id(e)]) for e in effects)
    oscillation = sum(e.frequency(arm, **given[id(e)]) for e in effects)
    disk = half_disk_limit(tableau) if oscillation else 0.0
    if oscillation and disk > 0.1:     # (Euler's half-disk is empty: nothing to plan)
        return h * (decay + oscillation), disk, "h |lambda|max"
    # h times the fastest real decay any effect adds (damping's d Lambda), at any pose.
    return h * decay, real_stability_limit(tableau), "d h lambda_max"


def stiff_names(effects, arm: ArmParameters) -> str:
    """The effects that make a step stiff, as the plan names them (damping+servo)."""
    return "+".join(e.name for e in effects if e.stiffness(arm) or e.frequency(arm))


def substeps_needed(ratio: float, limit: float) -> int:
    """Sub-steps for a step whose d h Lambda is `ratio`: 1 (plain RK4) while it is stable;
    anything above MAX_SUBSTEPS (even an infinite ratio) counts as MAX_SUBSTEPS + 1."""
    if ratio <= limit:
        return 1
    needed = ratio / (SUBSTEP_FRACTION * limit)
    return ceil(needed) if needed <= MAX_SUBSTEPS else MAX_SUBSTEPS + 1   # NaN lands here too


def substepping(step, substeps: int, stiff: str = "damping"):
    """step(f, y, h) as `substeps` equal steps of h / substeps; `step` itself when 1.
    Past MAX_SUBSTEPS every step raises ValueError instead of freezing its caller, naming
    `stiff`, what makes it stiff (stiff_names)."""
    if substeps == 1:
        return step
    if substeps > MAX_SUBSTEPS:
        def refuse(f, y, h):
            raise StepRefused(f"it needs more than {MAX_SUBSTEPS} sub-steps to stay stable; "
                             f"reduce step_size or the stiffness of {stiff}")
        return refuse

    def advance(f, y, h):
        h_sub = h / substeps
        for _ in range(substeps):
            y = step(f, y, h_sub)
        return y

    return advance


def exponential_radius(x: float, p: float, d: float) -> float:
    """Spectral radius of one exponential RK4 step (h = 1) of the winding's linear test
    problem i' = -x i - sqrt(p) u, u' = sqrt(p) i - d u: the pole x exact, the coupling
    (winding <-> inertia, squared frequency p) and the other decays d explicit."""
    e2, e, a21, a31, a32, a41, a43, b1, b2, b3, b4 = exponential_rk4(-x)
    w = p ** 0.5
    columns = []
    for i0, u0 in ((1.0, 0.0), (0.0, 1.0)):
        n = [(-w * u0, w * i0 - d * u0)]                  # (N, u') of each stage
        for i_k, u_k in ((e2 * i0, u0), (e2 * i0, u0), (e * i0, u0)):
            k = len(n)
            i_k += (a21 * n[0][0] if k == 1 else a31 * n[0][0] + a32 * n[1][0] if k == 2
                    else a41 * n[0][0] + a43 * n[2][0])
            u_k += 0.5 * n[k - 1][1] if k < 3 else n[2][1]
            n.append((-w * u_k, w * i_k - d * u_k))
        columns.append((e * i0 + b1 * n[0][0] + b2 * n[1][0] + b3 * n[2][0] + b4 * n[3][0],
                        u0 + (n[0][1] + 2.0 * n[1][1] + 2.0 * n[2][1] + n[3][1]) / 6.0))
    (m11, m21), (m12, m22) = columns
    half_trace, det = 0.5 * (m11 + m22), m11 * m22 - m12 * m21
    disc = half_trace * half_trace - det
    if disc >= 0.0:
        return max(abs(half_trace + disc ** 0.5), abs(half_trace - disc ** 0.5))
    return abs(det) ** 0.5                                # complex pair: |lambda|^2 = det


# The coupling's frequency varies with the pose (Lambda between its extremes): checked at
# these fractions of the worst one too, the region not being convex.
COUPLING_FRACTIONS = (1.0, 0.75, 0.5, 0.25, 0.1, 0.01)


def exact_substeps(effects, arm: ArmParameters, h: float) -> int:
    """Sub-steps that keep the exponential step stable on every exactly integrated
    winding's test problem (1: none), the other effects' real decays included."""
    windings = [e for e in effects if _exact(True, e) and hasattr(e, "coupling")]
    if not windings:
        return 1
    others = sum(e.stiffness(arm) for e in effects if e not in windings)
    n = 1
    while n <= MAX_SUBSTEPS:
        dt = h / n
        if all(exponential_radius(dt * lam, dt * dt * p * s, dt * others) <= 1.0 + 1e-12
               for e in windings for lam, p in e.coupling(arm) for s in COUPLING_FRACTIONS):
            return n
        n = n + 1 if n < 64 else ceil(1.25 * n)
    return MAX_SUBSTEPS + 1


def plan(tableau: ButcherTableau, effects, arm: ArmParameters, h: float, whole: bool = False):
    """(ratio, limit, sub-steps, what to tell a person or None): the
    sub-steps that keep the stiff effects stable at every elbow angle (1 = plain steps).
    Damping alone has real eigenvalues (the real-axis limit); springs and windings
    oscillate, so their bound |lambda| is kept inside the half-disk. An adaptive method
    controls its own error and sub-steps by itself. `whole` (a scene's stability_plan
    off, a stability study): no sub-steps, and the message says the steps may diverge."""
    ratio, limit, substeps, what = planned(tableau, effects, arm, h)
    message = None
    if substeps > 1 and whole:
        return ratio, limit, 1, (f"{what} = {ratio:.4g} ({stiff_names(effects, arm)}) exceeds "
                                 f"{tableau.name}'s stability limit {limit:.4g}; "
                                 "stability_plan off: each step is taken whole and may diverge")
    if substeps > 1:
        stiff = stiff_names(effects, arm)
        message = (f"{what} = {ratio:.4g} ({stiff}) exceeds {tableau.name}'s stability limit "
                   f"{limit:.4g}: each {h:g} s step is taken as {substeps} sub-steps")
        unstiff = [t.name for t in INTEGRATORS.values() if t.order >= tableau.order
                   and not t.adaptive and planned(t, effects, arm, h)[2] == 1]
        if unstiff:
            message += f"; {' or '.join(unstiff)} would take none (integrator: {unstiff[0]})"
    return ratio, limit, substeps, message


def planned(tableau: ButcherTableau, effects, arm: ArmParameters, h: float):
    """(ratio, limit, sub-steps, what is bounded) of plan, said to no one."""
    exact = integrates_decay_exactly(tableau)
    ratio, limit, what = bound(tableau, effects, arm, h, exact)
    substeps = 1 if getattr(tableau, "adaptive", False) else max(
        substeps_needed(ratio, limit), exact_substeps(effects, arm, h) if exact else 1)
    return ratio, limit, substeps, what


UNNAMED = "rk4, or exponential_rk4 where motor windings are stiff"   # integrator "" takes


def unstiff_method(effects, arm: ArmParameters, h: float) -> str:
    """The integrator of a scene that names none: exponential_rk4 where it takes fewer
    stability sub-steps than rk4 (motor windings stiff at this step: it integrates their
    decay exactly), else rk4 (the same bits where there are no windings)."""
    if any(getattr(e, "linear_decay", tuple)() for e in effects):
        taken = planned(RK4, effects, arm, h)[2]
        if taken > 1 and planned(EXPONENTIAL_RK4, effects, arm, h)[2] < taken:
            return EXPONENTIAL_RK4.name
    return RK4.name
