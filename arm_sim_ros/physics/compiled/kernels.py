"""The compiled loops of compiled.py as source text: Simulator.run with its error books
(run_books); the bare loop (the compiled limit) and a batch of arms are batched.py's.
compiled.py fills in the state's entries and the books' constants and compiles them with
numba.

run_books does what Simulator.step does on a smooth scene, step after step, with the same
operations in the same order: the planned sub-steps, the shadow beside them (shadow.py),
the accuracy books' checks on their schedule (accuracy.py: the step measured, a miss of the
tolerance taken again, the controller's count, the next check), the divergence check of
every state and the energy in play's peak every CHECK_EVERY steps (guard.py). Python's
max(a, b) keeps a unless b > a: so does `bigger`. Where Python would say something (a new
highest count, a tolerance out of reach, a lost estimate, a fault, a divergence) it stops
and leaves that step to Python (code 1: not taken; code 2: taken, its divergence check
Python's, the state before it in S).
"""
from .batched import BATCH

RUN = '''
@njit(cache=True)
def NAME(y, z, L, O, G, S, I, F, K, C, left, TMORE):
    """DOC"""
    steps, due, since, taken, n, every = I[0], I[1], I[2], I[3], I[4], I[5]
    floor, fcap, cap, most, capped, states = I[6], I[7], I[8], I[9], I[10], I[11]
    order, known, zvalid, lost, said_lost, fault = I[12], I[13], I[14], I[15], I[16], I[17]
    h, E0, R0, R1, largest, far, in_play = F[0], F[1], F[2], F[3], F[4], F[5], F[6]
    estimate, previous, tolerance, den, target = F[7], F[8], F[9], F[10], F[11]
    factor, lowest, orderf, stiff_below = F[12], F[13], F[14], F[15]
    state = ({items},)
    shade = ({zitems},)
    done, code = 0, 0
    unsensed, a0, a1 = state, K[0], K[1]
    while done < left:
SENSE
CHECK
        new_every, wanted, count = every, n, n     # count: this step's sub-steps
        z1, at_shadow = state, False              # the shadow's step, taken in the check
        if not check:                         # a plain step, the shadow beside it
PLAIN
        else:                                 # a check (accuracy.py)
CHECKED
            if known == 1:
                new_every = scheduled(G, L, every, steps + 1 - since)
AFTER
        # the shadow (shadow.Shadow.follow: from the corrected state, less the local error)
        local_known = known == 1 or check
        now_lost, now_far, now_shade = lost, far, shade
        if local_known and lost == 0:
SHADOW
            now_shade = corrected(z1, z, G if check else L, states)
            now_lost, now_far = landed(new, z, far)
        if now_lost == 1 and said_lost == 0:          # said by the books: Python's
            code = 1
            break
        if check:
            taken += (n * (steps - since) if n > 1 else 0) + (count if count > 1 else 0)
            since, estimate, previous = steps + 1, error, kept
            booked(L, G, states, count, wanted, orderf)
            # a new count's error is measured at the next step (accuracy.book)
            n, every, due, known = wanted, new_every, steps + (NEXT if wanted == count
                                                               else 1), 1
        if local_known and lost == 0:
            for k in range(states):
                O[k] = new[k] - z[k]
            zvalid, shade = 1, now_shade
        lost, far = now_lost, now_far
        before, state = state, new
        steps += 1
        done += 1
COMMIT
        r = residual(state, C, E0, R0, R1)    # guard.divergence and guard.audit
        ok, in_play = audited(state, r, C, E0, R0, lowest, in_play, fault,
                              steps % {CHECK_EVERY!r} == 0)
        if not ok:
            for k in range({width}):
                S[k] = before[k]
            code = 2
            break
        largest = bigger(largest, abs(r))
        if T.shape[0] > 0:                    # a trajectory asked for: this step's row
            recorded(T, done - 1, state, K)
RESTORE
    sound = steps if code != 2 else steps - 1
    handed(y, z, state, shade, I, F, steps, due, since, taken, n, every, known, zvalid, lost,
           largest, far, in_play, estimate, previous)
    return done, code, sound
'''


def run_loop(**parts) -> str:
    """RUN with its parts (NAME, MORE arguments, DOC, CHECK, PLAIN, CHECKED, AFTER, SHADOW,
    NEXT; SENSE, COMMIT and RESTORE where sensors act between steps: sensed.py) written in:
    run_books here, run_switching (switch_kernel.py) from the same loop. T: the rows of the
    trajectory asked for (torque.py), none when it has no rows."""
    text = RUN
    parts = dict(dict.fromkeys(("SENSE", "COMMIT", "RESTORE"), ""), **parts)
    for marker in ("NAME", "MORE", "DOC", "NEXT"):
        text = text.replace(marker, parts[marker])
    for marker in ("SENSE", "CHECK", "PLAIN", "CHECKED", "AFTER", "SHADOW", "COMMIT", "RESTORE"):
        text = text.replace(f"\n{marker}\n", "\n" + parts[marker] + "\n" if parts[marker]
                            else "\n")
    return text


BOOKS_PARTS = dict(     # run_books: a smooth scene's steps (Simulator.step)
    NAME='run_books', MORE='', NEXT='new_every', AFTER='',
    DOC='''Up to `left` steps of Simulator.step from y (in place), the books in I and F (read
    and written back; runs.Kernel names them), the shadow's state z, its local error L
    and offset O; G scratch, S the state the latest divergence check found sound.
    (steps taken, code: 0 all taken, 1 the next step is Python's, 2 the last step's
    divergence check is Python's, the state before it in S; the step of the latest state
    found sound).''',
    CHECK='''        check = steps >= due''',
    PLAIN='''            new = substepped(state, h, n, K)
            if not finite(new):
                code = 1
                break''',
    CHECKED='''            new, error, scaled = checked(state, h, n, K, G, factor, states, floor,
                                         stiff_below, orderf)
            if not (finite(new) and measured(G, states)):
                code = 1
                break
            kept = previous
            if tolerance != 0.0:
                wanted, kept = ask(n, scaled / den, previous, order, floor, fcap)
                first = scaled
                while scaled > target and count < cap:    # a miss: taken again
                    count = retake(count, scaled / den, order, cap)
                    new, error, scaled = checked(state, h, count, K, G, factor, states,
                                                 floor, stiff_below, orderf)
                    if not (finite(new) and measured(G, states)) or (
                            count >= {GIVE_UP!r} * n and scaled > {NO_GAIN!r} * first):
                        code = 1                          # said: Python's
                        break
                    wanted, kept = ask(count, scaled / den, kept, order, floor, fcap)
                if code == 1:
                    break
                if (wanted >= cap and capped == 0 and scaled > target) or (
                        wanted > most and wanted > 2 * max(1, most)):   # said: Python's
                    code = 1
                    break
            if count < stiff_below and lost == 0:   # accuracy.at_shadow: G measured there
                if zvalid == 0:
                    for k in range({width}):
                        z[k] = state[k] - O[k] if k < states else state[k]
                    shade = ({zitems},)
                    zvalid = 1
                z1, at_shadow = doubled(shade, h, count, K, G, factor, states, False, G)[0], True''',
    SHADOW='''            if not at_shadow:
                if zvalid == 0:
                    for k in range({width}):
                        z[k] = state[k] - O[k] if k < states else state[k]
                    now_shade = ({zitems},)
                z1 = substepped(now_shade, h, count, K)''')

HELPERS = '''
@njit(cache=True)
def bigger(a, b):
    return b if b > a else a


@njit(cache=True)
def smaller(a, b):
    return b if b < a else a


@njit(cache=True)
def substepped(state, h, n, K):
    """n equal sub-steps of h (stability.substepping); the step itself when 1."""
    if n == 1:
        return step(state, h, K)
    dt = h / n
    for k in range(n):
        state = step(state, dt, K)
    return state


@njit(cache=True)
def substepped_from(state, h, n, K, first):
    """substepped, the rhs at `state` given (`first`: a check computes it once)."""
    if n == 1:
        return step_from(state, h, K, first)
    dt = h / n
    state = step_from(state, dt, K, first)
    for k in range(n - 1):
        state = step(state, dt, K)
    return state


@njit(cache=True)
def grown(new, half, D, k, summed):
    """State k's difference of the step from its halves, less where they started apart."""
    return new[k] - half[k] - D[k] if summed else new[k] - half[k]


@njit(cache=True)
def sized(new, e0, e1, e2, e3):
    """accuracy.sized: (the step, its local error, its scaled error) of its states' errors."""
    scaled = bigger(bigger(bigger(e0, e1), e2 / (1.0 + abs(new[2]))), e3 / (1.0 + abs(new[3])))
    return new, bigger(bigger(bigger(e0, e1), e2), e3), scaled


@njit(cache=True)
def doubled(state, h, n, K, G, factor, states, summed, D):
    """accuracy.Accuracy.doubled: (the step as n sub-steps, its local error, its scaled
    error), the signed local error of every state into G (Richardson: 2n half sub-steps).
    Where `summed` (a switching step's sub-steps, accuracy.attempt), the halves start D
    from the state, and what this sub-step grows is added to D and, signed, to G."""
    hs = 0.5 * h / n
    if summed:
        new = substepped(state, h, n, K)
        half = ({ditems},)
        for k in range(2 * n):
            half = step(half, hs, K)
    else:                 # the step and its first half start from one state: one rhs there
        first = rhs({slopes}, K)
        new = substepped_from(state, h, n, K, first)
        half = step_from(state, hs, K, first)
        for k in range(2 * n - 1):
            half = step(half, hs, K)
    e0 = abs(grown(new, half, D, 0, summed) * factor)       # this (sub-)step's own, before
    e1 = abs(grown(new, half, D, 1, summed) * factor)       # D moves on
    e2 = abs(grown(new, half, D, 2, summed) * factor)
    e3 = abs(grown(new, half, D, 3, summed) * factor)
    for k in range(states):
        difference = grown(new, half, D, k, summed)
        if summed:
            D[k] = D[k] + difference
            G[k] = G[k] + difference * factor
        else:
            G[k] = difference * factor
    return sized(new, e0, e1, e2, e3)


@njit(cache=True)
def checked(state, h, n, K, G, factor, states, base, stiff_below, orderf):
    """accuracy.Accuracy.measure: (the step as n sub-steps, its local error, its scaled
    error), the signed local error of every state into G: a split step against other
    counts of its sub-steps as accuracy.compared takes them, else 2n halves."""
    if n < 2:
        return doubled(state, h, n, K, G, factor, states, False, G)
    m1, m2 = (n + 1) // 2, -(-n // 3)
    first = rhs({slopes}, K)
    new = substepped_from(state, h, n, K, first)
    if n >= {THREE_LEVELS!r} and m2 >= base and not m2 < stiff_below:
        r1, r2 = n / m1, n / m2
        det = (r1 ** orderf - 1.0) * (r2 ** (orderf + 1.0) - 1.0) - (
            r1 ** (orderf + 1.0) - 1.0) * (r2 ** orderf - 1.0)
        w1, w2 = r2 ** orderf * (r2 - 1.0) / det, -(r1 ** orderf) * (r1 - 1.0) / det
        one = substepped_from(state, h, m1, K, first)
        two = substepped_from(state, h, m2, K, first)
        for k in range(states):
            G[k] = w1 * (one[k] - new[k]) + w2 * (two[k] - new[k])
    else:
        m = (3 * n + 1) // 2
        fine = substepped_from(state, h, m, K, first)
        ratio = 1.0 - (n / m) ** orderf
        for k in range(states):
            G[k] = (new[k] - fine[k]) / ratio
    e0, e1, e2, e3 = abs(G[0]), abs(G[1]), abs(G[2]), abs(G[3])
    return sized(new, e0, e1, e2, e3)


@njit(cache=True)
def retake(n, ratio, order, cap):
    """controller.retake: the count a step that missed the tolerance is taken again at."""
    if isfinite(ratio):
        wanted = n * smaller({MAX_SHRINK!r}, ratio ** (1.0 / order))
    else:
        wanted = n * {MAX_SHRINK!r}
    return min(cap, max(n + 1, ceil(wanted - 1e-9)))


@njit(cache=True)
def finite(state):
    ok = True
    for v in state:
        ok = ok and isfinite(v)
    return ok and isfinite(state[0] + state[1] + state[2] + state[3])


@njit(cache=True)
def measured(G, states):
    """Every state's local error estimate finite."""
    ok = True
    for k in range(states):
        ok = ok and isfinite(G[k])
    return ok


@njit(cache=True)
def ask(n, ratio, previous, order, floor, cap):
    """controller.Control.ask after a step of n sub-steps measured at `ratio`:
    (the count asked for, the ratio kept)."""
    kept = ratio if isfinite(ratio) else previous
    if n <= floor and ratio * {SAFETY!r} <= 1.0:    # at the floor and met: no pow to take
        return n, kept
    if not isfinite(ratio):
        wanted = min(cap, max(floor, ceil(n * {MAX_SHRINK!r})))
    else:
        r, p = bigger(ratio, 1e-12), bigger(previous, 1e-12)
        factor = r ** ({KI!r} / order) * (r / p) ** ({KP!r} / order)
        w = n * smaller({MAX_SHRINK!r}, bigger(1.0 / {MAX_GROWTH!r}, factor))
        if w < n and w > {KEEP!r} * n:
            wanted = n
        else:
            wanted = max(floor, min(cap, ceil(w - 1e-9)))
    return wanted, kept


@njit(cache=True)
def scheduled(G, L, every, spacing):
    """shadow.next_every: steps to the next check after one that measured G (L predicted),
    `spacing` steps after the last."""
    change, size = 0.0, {ROUNDING!r}
    for k in range(4):
        change = bigger(change, abs(G[k] - L[k])) if k else abs(G[k] - L[k])
    for k in range(4):
        size = bigger(size, abs(G[k]))
    for k in range(4):
        size = bigger(size, abs(L[k]))
    if change > {ROUGH!r} * size:
        return max({MIN_EVERY!r}, every // 2)
    if change < {SMOOTH!r} * size and spacing >= every:
        return min({MAX_EVERY!r}, 2 * every)
    return every


@njit(cache=True)
def corrected(z1, z, local, states):
    """The shadow's step z1 less the local error (Shadow.land), into z and returned."""
    for k in range({width}):
        z[k] = z1[k] - local[k] if k < states else z1[k]
    return ({zitems},)


@njit(cache=True)
def landed(new, z, far):
    """Shadow.land beside the motion's new state: (lost, the largest distance so far)."""
    o0, o1, o2, o3 = new[0] - z[0], new[1] - z[1], new[2] - z[2], new[3] - z[3]
    distance = bigger(bigger(bigger(abs(o0), abs(o1)), abs(o2)), abs(o3))
    scaled_off = bigger(bigger(bigger(abs(o0), abs(o1)), abs(o2) / (1.0 + abs(new[2]))),
                        abs(o3) / (1.0 + abs(new[3])))
    lost = 0
    if not scaled_off <= {LOST!r}:
        lost, distance = 1, bigger(far, {LOST!r})
    return lost, bigger(far, distance)


@njit(cache=True)
def booked(L, G, states, n, wanted, orderf):
    """The shadow's local error from now on: the check's G, predicted at the new count."""
    scale = (n / wanted) ** orderf if wanted != n else 1.0
    for k in range(states):
        L[k] = G[k] * scale if wanted != n else G[k]


@njit(cache=True)
def handed(y, z, state, shade, I, F, steps, due, since, taken, n, every, known, zvalid, lost,
           largest, far, in_play, estimate, previous):
    """The run's state, shadow and books written back for Python (runs.Kernel)."""
    for k in range({width}):
        y[k], z[k] = state[k], shade[k]
    I[0], I[1], I[2], I[3], I[4], I[5] = steps, due, since, taken, n, every
    I[13], I[14], I[15] = known, zvalid, lost
    F[4], F[5], F[6], F[7], F[8] = largest, far, in_play, estimate, previous


@njit(cache=True)
def audited(state, r, C, E0, R0, lowest, in_play, fault, peak):
    """guard.divergence and guard.audit of a state whose residual is r (`peak`: the energy
    in play keeps its peak): (sound and the books close, the energy in play); False:
    Python's to say."""
    expected = E0 - lowest + abs(inputs(state, R0))
    if not abs(r) <= {FLOOR!r} + bigger(in_play, expected) or not bigger(
            abs(state[0]), abs(state[1])) <= {MAX_ANGLE!r}:
        return False, in_play
    play = bigger(in_play, energy(state, C) - lowest) if peak else in_play
    if fault == 0 and not abs(r) <= {BOOKS_FRACTION!r} * ({FLOOR!r} + bigger(play, expected)):
        return False, in_play
    return True, play

'''
KERNELS = HELPERS + run_loop(**BOOKS_PARTS) + BATCH
