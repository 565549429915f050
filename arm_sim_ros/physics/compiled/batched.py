"""Many simulators of one scene structure stepped in one compiled call (run_many, in every
module build.py writes; rollouts/batched.py calls it): each row of the stacked arrays is
one simulator's kernel arrays (runs.Kernel), stepped by run_books as its own Kernel.run
would step it, rows in parallel (numba's prange over numba's threads). Rows are
independent, so the numbers do not depend on the thread count. R[row] gets what run_books
returns (steps taken, code, the step of the latest state found sound): a row handed back
is finished by its own Kernel.run, from the same arrays.
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
