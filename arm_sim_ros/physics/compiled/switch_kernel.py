"""The compiled run of a switching scene's steps in one mode (compiled.py, switch_run.py), as
source text: each mode's module holds it beside the mode's rhs, step and switching
functions (dynamics.mode_functions).

A step of a switching scene in which no switching function comes near zero is the mode's
smooth sub-steps (events.Switching.advance), and the shadow's step beside it is its twin's
smooth sub-steps in the same mode (shadow.Twin). run_switching takes such steps, with the
error books' checks (accuracy.Accuracy.switching: each sub-step doubled, the errors
summed), the controller's count, the schedule, the divergence checks and the largest
|residual|, as kernels.run_books does for a smooth scene. It hands back to Python, before
taking it, every step in which anything could switch: a switching function negative at a
sub-step's end, or one that events.py's dense check (dense.ended: the same Hermite
instants, the same operations) would re-step to; a driver within 1e-9 of its voltage limit (its count is
Python's); anything run_books hands back. Python retakes that step from the same state,
so it cannot be missed: the rule errs only toward handing back.
"""
from .kernels import run_loop

SWITCH_KERNEL = '''
from math import sqrt


@njit(cache=True)
def holds(g):
    """Every switching function >= 0 (NaN: not)."""
    for v in g:
        if not v >= 0.0:
            return False
    return True


@njit(cache=True)
def root_in(a, b, c):
    """dense._root: the one root in (0, 1) of a s^2 + b s + c."""
    root = sqrt(bigger(b * b - 4.0 * a * c, 0.0))
    s = (-b - root) / (2.0 * a)
    if 0.0 <= s <= 1.0:
        return s
    s = (-b + root) / (2.0 * a)
    if 0.0 <= s <= 1.0:
        return s
    return 0.5


@njit(cache=True)
def extrema_into(p0, p1, m0, m1, E, count):
    """dense.extrema, the fractions written into E from `count` on: the new count."""
    a = 6.0 * (p0 - p1) + 3.0 * (m0 + m1)
    b = -6.0 * (p0 - p1) - 4.0 * m0 - 2.0 * m1
    if a != 0.0 and b * (2.0 * a + b) < 0.0:
        E[count] = -0.5 * b / a
        count += 1
        low = m0 - 0.25 * b * b / a
        if (low < 0.0) != (m0 < 0.0) or (low < 0.0) != (m1 < 0.0):
            root = sqrt(bigger(b * b - 4.0 * a * m0, 0.0))
            s = (-b - root) / (2.0 * a)
            if 0.0 < s < 1.0:
                E[count] = s
                count += 1
            s = (-b + root) / (2.0 * a)
            if 0.0 < s < 1.0:
                E[count] = s
                count += 1
    elif m0 * m1 < 0.0:
        E[count] = m0 / (m0 - m1) if a == 0.0 else root_in(a, b, m0)
        count += 1
    return count


@njit(cache=True)
def near(y0, y1, dt, K, E):
    """True where dense.ended would not return None for the sub-step y0 -> y1: a switching
    function negative at its end, or one at a Hermite instant nearer zero than its dip
    (dense.ended then re-steps; here the step is left to Python)."""
    g1 = guard({gitems1}, K)
    if not holds(g1):
        return True
    d, e = y0[0] - y1[0], y0[1] - y1[1]
    v0, v1, w0, w1 = y0[2] * dt, y1[2] * dt, y0[3] * dt, y1[3] * dt
    if v0 * v1 >= 0.0 and w0 * w1 >= 0.0 and (3.0 * d + 2.0 * v0 + v1) * (
            3.0 * d + v0 + 2.0 * v1) <= 0.0 and (3.0 * e + 2.0 * w0 + w1) * (
            3.0 * e + w0 + 2.0 * w1) <= 0.0:
        return False
    count = extrema_into(y0[0], y1[0], v0, v1, E, 0)
    count = extrema_into(y0[1], y1[1], w0, w1, E, count)
    if count == 0:
        return False
    g0 = guard({gitems0}, K)
    for c in range(count):
        s = E[c]
        s2, s3 = s * s, s * s * s
        h00, h10, h01, h11 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, 3 * s2 - 2 * s3, s3 - s2
        d00, d10, d01, d11 = 6 * (s2 - s), 3 * s2 - 4 * s + 1, 6 * (s - s2), 3 * s2 - 2 * s
        p1 = h00 * y0[0] + h01 * y1[0] + dt * (h10 * y0[2] + h11 * y1[2])
        p2 = h00 * y0[1] + h01 * y1[1] + dt * (h10 * y0[3] + h11 * y1[3])
        r1 = (d00 * y0[0] + d01 * y1[0]) / dt + d10 * y0[2] + d11 * y1[2]
        r2 = (d00 * y0[1] + d01 * y1[1]) / dt + d10 * y0[3] + d11 * y1[3]
        gs = guard({hitems}, K)
        for k in range(len(gs)):
            if gs[k] < bigger(g0[k] + s * (g1[k] - g0[k]) - gs[k], 0.0):
                return True
    return False


@njit(cache=True)
def smooth_step(state, h, n, K, E):
    """(the step as n sub-steps, False) as events.Switching.advance takes it in one mode;
    (.., True) where the mode could end in a sub-step (Python's, then)."""
    if n == 1:
        new = step(state, h, K)
        return new, near(state, new, h, K, E)
    dt = h / n
    for k in range(n):
        new = step(state, dt, K)
        if near(state, new, dt, K, E):
            return new, True
        state = new
    return state, False


@njit(cache=True)
def checked_step(state, h, n, K, E, G, D, states, factor):
    """accuracy.Accuracy.switching's attempt of a step in one mode: (the step, near as in
    smooth_step, the summed error, the summed scaled error), every sub-step doubled, the
    halves going on from their own state (D apart), the signed errors summed into G."""
    for k in range(states):
        G[k] = 0.0
        D[k] = 0.0
    total, scaled = 0.0, 0.0
    dt = h if n == 1 else h / n
    for c in range(n):
        new, error, part = doubled(state, dt, 1, K, G, factor, states, True, D)
        if near(state, new, dt, K, E):
            return new, True, total, scaled
        total += error
        scaled += part
        state = new
    return state, False, total, scaled


'''


SWITCH_PARTS = dict(    # run_switching: a switching scene's steps in one mode
    NAME="run_switching", MORE=", X, E, D",
    # a first estimate (none predicted, accuracy.book's `soon`): checked at the next step
    NEXT="(new_every if known == 1 else 1)",
    DOC='''run_books for a switching scene in one mode: up to `left` steps from y, each
    handed back (code 1) where anything could switch. X: (sliding joint 1, sliding joint 2,
    the Stribeck dip's edge |q̇| within which a sliding joint's step is checked, a driver's
    check on); E scratch.''',
    CHECK='''        # a check when due, and a joint sliding through Stribeck's dip: always (events.steep)
        check = steps >= due or (X[0] != 0.0 and abs(state[2]) < X[2]) or (
            X[1] != 0.0 and abs(state[3]) < X[2])''',
    PLAIN='''            new, ends = smooth_step(state, h, n, K, E)
            if ends or not finite(new):
                code = 1
                break''',
    CHECKED='''            new, ends, total, summed = checked_step(state, h, n, K, E, G, D, states, factor)
            if ends or not finite(new):
                code = 1
                break
            error, scaled = total + 0.0, summed + 0.0
            if not measured(G, states):
                code = 1
                break
            kept = previous
            if tolerance != 0.0:
                if summed > target:           # retaken, or said unreachable: Python's
                    code = 1
                    break
                wanted, kept = ask(n, summed / den, previous, order, floor, fcap)
                if wanted > most and wanted > 2 * max(1, most):   # said: Python's
                    code = 1
                    break
            if known == 0:                    # a first estimate: the schedule starts afresh
                new_every = {FIRST_EVERY!r}''',
    AFTER='''        if X[3] != 0.0 and driven(new, K) >= 0.0:   # the driver's count: Python's
            code = 1
            break''',
    SHADOW='''            if zvalid == 0:                   # its twin finds its mode afresh: Python's
                code = 1
                break
            z1, ends = smooth_step(shade, h, n, K, E)   # its twin's step in the same mode
            if ends:
                code = 1
                break''')
SWITCH_KERNEL += run_loop(**SWITCH_PARTS)


def driver_source(dynamics) -> str:
    """driven(y, K): how far the drivers' voltage (the policy's torque after the effort
    limits, as dynamics.driver_check reads it) comes within 1e-9 of its limit (>= 0: near
    or beyond), from the mode-free stage terms; -1.0 without a voltage limit."""
    effects = [e.name for e in dynamics.active]
    motors = dict(zip(effects, dynamics.active)).get("motors")
    if motors is None or motors.voltage_limit is None:
        return "def driven(y):\n    return -1.0\n"
    terms = [line for effect in dynamics.active[:effects.index("motors")]
             for line in effect.terms()]
    width = 4 + len(dynamics.extra)
    names = ", ".join(["q1", "q2", "u1", "u2", *dynamics.extra])
    reads = ", ".join(f"y[{k}]" for k in range(width))
    return "\n".join(["def driven(y):", f"    {names}, = {reads}",
                      *("    " + line for line in terms),
                      "    return max(abs(DRIVE1 * t1) * (1.0 + 1e-9) - VLIM1, "
                      "abs(DRIVE2 * t2) * (1.0 + 1e-9) - VLIM2)"]) + "\n"


def template_items(states_width: int) -> dict:
    """The state's entries the template reads (compiled.module_source fills them in)."""
    extra = range(4, states_width)
    return {"gitems1": ", ".join(f"y1[{k}]" for k in range(states_width)),
            "gitems0": ", ".join(f"y0[{k}]" for k in range(states_width)),
            "hitems": ", ".join(["p1", "p2", "r1", "r2", *(
                f"y0[{k}] + s * (y1[{k}] - y0[{k}])" for k in extra)])}
