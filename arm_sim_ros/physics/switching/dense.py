"""Switches inside a sub-step whose ends both hold: the guards between the ends (events.py).

A sub-step's guards are checked at its end, but a mode can also end and come back within
it: a fast arm's Coulomb friction drives a velocity through zero and back, a joint passes
a hard stop and turns back before the end. Between the ends the motion is read from the
cubic Hermite of each angle through (q, q̇) at both ends, whose derivative is a quadratic
for q̇: no further evaluation of the dynamics. A guard on an angle (an impact, entering or
leaving a compliant limit) has an interior minimum only where that quadratic changes
sign, one on a velocity (a sliding joint's stop) only at its vertex; every guard is
evaluated at those instants on the Hermite. Where one comes nearer zero than its dip below
the chord of its end values (the interpolant's error is of that size), the sub-step is
taken again to that instant; a guard negative on the method's own state there is a switch,
located before that instant like any other. A sub-step without a turning point or an
inflection costs a few multiplications per joint.
"""
from __future__ import annotations

from math import sqrt


def extrema(p0: float, p1: float, m0: float, m1: float) -> list[float]:
    """Fractions s in (0, 1) where the cubic Hermite through angles p0, p1 with end slopes
    m0, m1 (q̇ x the sub-step) turns (q̇ = 0) or inflects (q̈ = 0)."""
    # the Hermite's slope per unit s: a s² + b s + m0, m1 at s = 1
    a = 6.0 * (p0 - p1) + 3.0 * (m0 + m1)
    b = -6.0 * (p0 - p1) - 4.0 * m0 - 2.0 * m1
    out = []
    if a != 0.0 and b * (2.0 * a + b) < 0.0:        # the slope's vertex is inside
        vertex = -0.5 * b / a
        out.append(vertex)
        low = m0 - 0.25 * b * b / a                   # the slope there
        if (low < 0.0) != (m0 < 0.0) or (low < 0.0) != (m1 < 0.0):
            root = sqrt(max(b * b - 4.0 * a * m0, 0.0))
            out += [s for s in ((-b - root) / (2.0 * a), (-b + root) / (2.0 * a)) if 0.0 < s < 1.0]
    elif m0 * m1 < 0.0:                              # monotone slope, one sign change
        out.append(m0 / (m0 - m1) if a == 0.0 else _root(a, b, m0))
    return out


def _root(a: float, b: float, c: float) -> float:
    """The one root in (0, 1) of a s² + b s + c, whose ends c and a + b + c differ in sign."""
    root = sqrt(max(b * b - 4.0 * a * c, 0.0))
    for s in ((-b - root) / (2.0 * a), (-b + root) / (2.0 * a)):
        if 0.0 <= s <= 1.0:
            return s
    return 0.5                # rounding put both just outside: read the middle instead


def between(y0, y1, dt: float, s: float) -> tuple:
    """The state at fraction s of the sub-step on the Hermite (extra states linearly)."""
    s2, s3 = s * s, s * s * s
    h00, h10, h01, h11 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, 3 * s2 - 2 * s3, s3 - s2
    d00, d10, d01, d11 = 6 * (s2 - s), 3 * s2 - 4 * s + 1, 6 * (s - s2), 3 * s2 - 2 * s
    q = [h00 * y0[j] + h01 * y1[j] + dt * (h10 * y0[2 + j] + h11 * y1[2 + j]) for j in (0, 1)]
    u = [(d00 * y0[j] + d01 * y1[j]) / dt + d10 * y0[2 + j] + d11 * y1[2 + j] for j in (0, 1)]
    return (*q, *u, *(a + s * (b - a) for a, b in zip(y0[4:], y1[4:])))


def ended(step, rhs, guard, width: int, y0, y1, dt: float) -> float | None:
    """The time (<= dt) by which the mode of a sub-step y0 -> y1 ended, or None when it
    holds throughout: dt when a guard is negative at the end, an earlier instant when one
    is negative inside (on a re-step to it, found from the Hermite)."""
    g1 = guard(*y1[:width])
    if not g1 or min(g1) < 0.0:
        return dt if g1 else None
    d, e, v0, v1, w0, w1 = y0[0] - y1[0], y0[1] - y1[1], y0[2] * dt, y1[2] * dt, \
        y0[3] * dt, y1[3] * dt
    # no slope changes sign and no curvature (∝ 3d + 2m0 + m1 at the start, 3d + m0 + 2m1
    # at the end) does: neither angle nor velocity has an interior extremum
    if v0 * v1 >= 0.0 and w0 * w1 >= 0.0 and (3.0 * d + 2.0 * v0 + v1) * (
            3.0 * d + v0 + 2.0 * v1) <= 0.0 and (3.0 * e + 2.0 * w0 + w1) * (
            3.0 * e + w0 + 2.0 * w1) <= 0.0:
        return None
    found = extrema(y0[0], y1[0], v0, v1) + extrema(y0[1], y1[1], w0, w1)
    if not found:
        return None
    g0 = guard(*y0[:width])
    for s in sorted(found):
        gs = guard(*between(y0, y1, dt, s)[:width])
        if any(g < max(a + s * (b - a) - g, 0.0) for g, a, b in zip(gs, g0, g1)):
            t = s * dt
            if min(guard(*step(rhs, y0, t)[:width])) < 0.0:   # the method's own state
                return t
    return None
