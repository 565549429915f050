"""Many simulators of one scene structure stepped in one compiled call (run_many, in every
module build.py writes; rollouts/batched.py calls it): each row of the stacked arrays is
one simulator's kernel arrays (runs.Kernel), stepped by run_books as its own Kernel.run
would step it, rows in parallel (numba's prange over numba's threads). Rows are
independent, so the numbers do not depend on the thread count. R[row] gets what run_books
returns (steps taken, code, the step of the latest state found sound): a row handed back
is finished by its own Kernel.run, from the same arrays. BATCH: arms stepped together with
nothing else (Batch), and the bare loop, the compiled limit.
"""
from __future__ import annotations

RUN_MANY = '''
@njit(cache=True, parallel=True)
def run_many(Y, Z, L, O, G, S, I, F, K, C, left, T, RMANY):
    """run_books of every row, rows in parallel; R[row]: (done, code, sound)."""
    for a in prange(Y.shape[0]):
        done, code, sound = run_books(Y[a], Z[a], L[a], O[a], G[a], S[a], I[a], F[a], K[a],
                                      C[a], left, T[a]ROWS)
        R[a, 0] = done
        R[a, 1] = code
        R[a, 2] = sound
'''


def run_many(more: str) -> str:
    """RUN_MANY for a run_books whose further arguments are `more` (", RS, RI ..." or "")."""
    rows = "".join(f", {name}[a]" for name in more.replace(",", " ").split())
    return RUN_MANY.replace("MANY", more).replace("ROWS", rows)


BATCH = '''
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
