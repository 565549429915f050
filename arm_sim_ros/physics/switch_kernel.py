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
def checked_step(state, h, n, K, E, G, states, factor):
    """accuracy.Accuracy.switching's attempt of a step in one mode: (the step, near as in
    smooth_step, the summed error, the summed scaled error), every sub-step doubled, the
    signed errors summed into G."""
    for k in range(states):
        G[k] = 0.0
    total, scaled = 0.0, 0.0
    dt = h if n == 1 else h / n
    for c in range(n):
        new = step(state, dt, K)
        if near(state, new, dt, K, E):
            return new, True, total, scaled
        hs = 0.5 * dt / 1
        half = step(step(state, hs, K), hs, K)
        e0 = abs((new[0] - half[0]) * factor)
        e1 = abs((new[1] - half[1]) * factor)
        e2 = abs((new[2] - half[2]) * factor)
        e3 = abs((new[3] - half[3]) * factor)
        for k in range(states):
            G[k] = G[k] + (new[k] - half[k]) * factor
        total += bigger(bigger(bigger(e0, e1), e2), e3)
        scaled += bigger(bigger(bigger(e0, e1), e2 / (1.0 + abs(new[2]))),
                         e3 / (1.0 + abs(new[3])))
        state = new
    return state, False, total, scaled


@njit(cache=True)
def run_switching(y, z, L, O, G, S, I, F, K, C, left, X, E):
    """run_books for a switching scene in one mode: up to `left` steps from y, each handed
    back (code 1) where anything could switch. X: (sliding joint 1, sliding joint 2, the
    Stribeck dip's edge |q̇| within which a sliding joint's step is checked, a driver's
    check on); E scratch."""
    steps, due, since, taken, n, every = I[0], I[1], I[2], I[3], I[4], I[5]
    floor, fcap, cap, most, capped, states = I[6], I[7], I[8], I[9], I[10], I[11]
    order, known, zvalid, lost, said_lost, fault = I[12], I[13], I[14], I[15], I[16], I[17]
    h, E0, R0, R1, largest, far, in_play = F[0], F[1], F[2], F[3], F[4], F[5], F[6]
    estimate, previous, tolerance, den, target = F[7], F[8], F[9], F[10], F[11]
    factor, lowest, orderf = F[12], F[13], F[14]
    state = ({items},)
    shade = ({zitems},)
    done, code, sound = 0, 0, -1
    while done < left:
        # a check when due, and a joint sliding through Stribeck's dip: always (events.steep)
        check = steps >= due or (X[0] != 0.0 and abs(state[2]) < X[2]) or (
            X[1] != 0.0 and abs(state[3]) < X[2])
        new_every, wanted = every, n
        if not check:                         # a plain step, the shadow beside it
            new, ends = smooth_step(state, h, n, K, E)
            if ends or not finite(new):
                code = 1
                break
        else:                                 # a check: every sub-step doubled
            new, ends, total, summed = checked_step(state, h, n, K, E, G, states, factor)
            if ends or not finite(new):
                code = 1
                break
            error, scaled = total + 0.0, summed + 0.0
            ok = True
            for k in range(states):
                ok = ok and isfinite(G[k])
            if not ok:
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
            if known == 1:                    # shadow.next_every
                change, size = 0.0, 0.0
                for k in range(4):
                    change = bigger(change, abs(G[k] - L[k])) if k else abs(G[k] - L[k])
                for k in range(4):
                    size = bigger(size, abs(G[k])) if k else abs(G[k])
                for k in range(4):
                    size = bigger(size, abs(L[k]))
                if change > {ROUGH!r} * size:
                    new_every = max({MIN_EVERY!r}, every // 2)
                elif change < {SMOOTH!r} * size:
                    new_every = min({MAX_EVERY!r}, 2 * every)
        if X[3] != 0.0 and driven(new, K) >= 0.0:   # the driver's count: Python's
            code = 1
            break
        # the shadow: its twin's step in the same mode (shadow.Twin, Shadow.follow)
        local_known = known == 1 or check
        now_lost, now_far, now_shade = lost, far, shade
        if local_known and lost == 0:
            if zvalid == 0:                   # its twin finds its mode afresh: Python's
                code = 1
                break
            z1, ends = smooth_step(shade, h, n, K, E)
            if ends:
                code = 1
                break
            for k in range({width}):
                z[k] = z1[k] - (G[k] if check else L[k]) if k < states else z1[k]
            now_shade = ({zitems},)
            o0, o1, o2, o3 = new[0] - z[0], new[1] - z[1], new[2] - z[2], new[3] - z[3]
            distance = bigger(bigger(bigger(abs(o0), abs(o1)), abs(o2)), abs(o3))
            scaled_off = bigger(bigger(bigger(abs(o0), abs(o1)), abs(o2) / (1.0 + abs(new[2]))),
                                abs(o3) / (1.0 + abs(new[3])))
            if not scaled_off <= {LOST!r}:
                now_lost, distance = 1, bigger(far, {LOST!r})
            now_far = bigger(far, distance)
        if check:
            if now_lost == 1 and said_lost == 0:      # said by the books: Python's
                code = 1
                break
            taken += (n * (steps - since) if n > 1 else 0) + (n if n > 1 else 0)
            since, estimate, previous = steps + 1, error, kept
            scale = (n / wanted) ** orderf if wanted != n else 1.0
            for k in range(states):
                L[k] = G[k] * scale if wanted != n else G[k]
            # a first estimate (none predicted): checked again at the next step
            n, every, due, known = wanted, new_every, steps + (
                new_every if known == 1 else 1), 1
        if local_known and lost == 0:
            for k in range(states):
                O[k] = new[k] - z[k]
            zvalid, shade = 1, now_shade
        lost, far = now_lost, now_far
        state = new
        steps += 1
        done += 1
        if steps % {CHECK_EVERY!r} == 0:      # guard.divergence and guard.audit
            r = residual(state, C, E0, R0, R1)
            expected = E0 - lowest + abs(inputs(state, R0))
            if not abs(r) <= {FLOOR!r} + bigger(in_play, expected) or not bigger(
                    abs(state[0]), abs(state[1])) <= {MAX_ANGLE!r}:
                code = 2
                break
            play = bigger(in_play, energy(state, C) - lowest)
            if fault == 0 and not abs(r) <= {BOOKS_FRACTION!r} * ({FLOOR!r} + bigger(
                    play, expected)):
                code = 2
                break
            in_play, sound = play, steps
            for k in range({width}):
                S[k] = state[k]
        largest = bigger(largest, abs(residual(state, C, E0, R0, R1)))
    for k in range({width}):
        y[k], z[k] = state[k], shade[k]
    I[0], I[1], I[2], I[3], I[4], I[5] = steps, due, since, taken, n, every
    I[13], I[14], I[15] = known, zvalid, lost
    F[4], F[5], F[6], F[7], F[8] = largest, far, in_play, estimate, previous
    return done, code, sound
'''


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
