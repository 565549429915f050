"""The compiled loops of compiled.py as source text: plain steps in one call (with the
error books' shadow beside them, shadow.py), the bare loop (the compiled limit) and a
batch of arms. compiled.py fills in the state's entries and compiles them with numba."""

KERNELS = '''
@njit(cache=True)
def advance(y, h, steps, substeps, K, C, E0, R0, R1, largest):
    """Up to `steps` plain steps from y (in place); stops before a non-finite one.
    (steps taken, largest |residual|). No shadow: advance_shadowed with none to follow."""
    done, largest, far, gone = advance_shadowed(y, y, y, 0, h, steps, substeps, K, C, E0, R0,
                                                R1, largest, 0.0, -1.0)
    return done, largest


@njit(cache=True)
def advance_shadowed(y, z, L, n, h, steps, substeps, K, C, E0, R0, R1, largest, far, lost):
    """advance, the shadow beside it (shadow.py: z -> step(z) - L on the first n states, the
    largest |y - z| in `far`, not followed past `lost`; none if `lost` < 0).
    (done, largest, far, lost or not)"""
    state = ({items},)
    shade = ({zitems},)
    dt = h / substeps
    done = 0
    gone = not lost >= 0.0
    for m in range(steps):
        new = step(state, h, K) if substeps == 1 else state
        if substeps > 1:
            for k in range(substeps):
                new = step(new, dt, K)
        finite = True
        for v in new:
            finite = finite and isfinite(v)
        if not finite:
            break
        state = new
        done += 1
        r = abs(residual(state, C, E0, R0, R1))
        if r > largest:
            largest = r
        if gone:
            continue
        nz = step(shade, h, K) if substeps == 1 else shade
        if substeps > 1:
            for k in range(substeps):
                nz = step(nz, dt, K)
        shade = nz
        for k in range({width}):
            z[k] = shade[k] - L[k] if k < n else shade[k]
        shade = ({zitems},)
        o0, o1, o2, o3 = state[0] - z[0], state[1] - z[1], state[2] - z[2], state[3] - z[3]
        distance = max(abs(o0), abs(o1), abs(o2), abs(o3))
        scaled = max(abs(o0), abs(o1), abs(o2) / (1.0 + abs(state[2])),
                     abs(o3) / (1.0 + abs(state[3])))
        if not scaled <= lost:
            gone = True
            distance = max(far, lost)
        far = max(far, distance)
    for k in range({width}):
        y[k] = state[k]
    return done, largest, far, gone


@njit(cache=True)
def step_array(y, h, K):
    """One step from the array y (numba types an array argument faster than a tuple)."""
    return step(({items},), h, K)


@njit(cache=True)
def bare(y, h, total, K):
    """`total` steps of h from y (in place), nothing else: the compiled limit."""
    state = ({items},)
    for n in range(total):
        state = step(state, h, K)
    for k in range({width}):
        y[k] = state[k]


@njit(cache=True, parallel=True)
def advance_batch(Y, h, total, P):
    """`total` steps of h for every arm (columns of Y, in place), arm a reading P[a]."""
    for a in prange(Y.shape[1]):
        K = P[a]
        state = ({columns},)
        for n in range(total):
            state = step(state, h, K)
        for k in range({width}):
            Y[k, a] = state[k]
'''
