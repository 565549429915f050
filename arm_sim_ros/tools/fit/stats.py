"""What a fit's optimum is worth: standard errors, correlations, what the data do not
excite, and the error on the held-out validation segment.

Covariance of the scaled unknowns (parameters and segment start states together) is
s² (JᵀJ)⁻¹ from the Jacobian J at the optimum, s² = Σr² / (m − n) the residual variance;
a parameter's standard error is its diagonal entry's root times its scale, the start
states marginalised out. A parameter whose column of J is (next to) zero does not move the
simulated trajectory at all: it is reported without a standard error and warned about.
"""
from __future__ import annotations

import numpy as np

from .problem import Problem, solve

UNMOVED = 1e-9            # a column this small against the largest: the data ignore it
LOOSE = 0.1               # a relative standard error above this is warned about
CORRELATED = 0.995        # |correlation| above this: only a combination is identified
MISFIT = 4.0              # χ² per residual above this (RMS > 2 σ): the model lacks something


def uncertainty(jac: np.ndarray, residuals: np.ndarray, n: int) -> dict:
    """Standard errors (scaled) of the first n unknowns and their correlation matrix."""
    m, total = jac.shape
    variance = float(residuals @ residuals) / max(1, m - total)
    norms = np.linalg.norm(jac, axis=0)
    moved = norms > UNMOVED * norms.max()
    _, s, vt = np.linalg.svd(jac[:, moved], full_matrices=False)
    inverse = np.where(s > 1e-12 * s[0], 1.0 / np.maximum(s, 1e-300) ** 2, np.inf)
    covariance = np.full((total, total), np.nan)
    kept = np.flatnonzero(moved)
    covariance[np.ix_(kept, kept)] = variance * (vt.T * inverse) @ vt
    block = covariance[:n, :n]
    se = np.sqrt(np.diag(block))
    with np.errstate(invalid="ignore", divide="ignore"):
        correlation = block / np.outer(se, se)
    return {"se": se, "correlation": correlation, "variance": variance,
            "moved": moved[:n]}


def warnings_for(problem: Problem, values, se, correlation, moved, runs, names,
                 chi2: float) -> list[str]:
    """One line per parameter the recording does not identify, per pair it cannot tell
    apart, and one if the best fit still misses the recording by more than its noise."""
    lines = []
    if chi2 > MISFIT:
        lines.append(f"the fitted simulation misses the recording by {chi2 ** 0.5:.3g} x its "
                     "noise (RMS): the base scene lacks something the arm has; free more keys")
    for i, p in enumerate(problem.free):
        joint = names[p.index] if p.index is not None else "either joint"
        if p.field == "friction" and p.name == "static" and not stuck(runs, p.index):
            lines.append(f"{p.key}: the {joint} never stuck; not identifiable from this "
                         "recording (record motions that stop and start again)")
        elif not moved[i]:
            lines.append(f"{p.key}: the simulated motion does not depend on it; not "
                         "identifiable from this recording")
        elif not se[i] <= LOOSE * max(abs(values[i]), p.typical * 1e-3):
            lines.append(f"{p.key}: ± {se[i]:.3g} {p.unit} on {values[i]:.4g}; barely "
                         "identifiable from this recording (excite what it acts on more)")
    n = len(problem.free)
    for i in range(n):
        for j in range(i + 1, n):
            if abs(correlation[i, j]) > CORRELATED:
                lines.append(f"{problem.free[i].key} and {problem.free[j].key} are "
                             f"{correlation[i, j]:+.4f} correlated: this recording identifies "
                             "a combination of them, not each")
    return lines


def stuck(runs, joint) -> bool:
    """Whether the fitted simulation ever held the joint (any, for None) still for two or
    more samples in a row: a stuck joint's velocity is exactly zero."""
    joints = (0, 1) if joint is None else (joint,)
    for run in runs:
        for j in joints:
            still = run[:, 2 + j] == 0.0
            if np.any(still[1:] & still[:-1]):
                return True
    return False


def validate(problem: Problem, xp, deadline=None) -> dict | None:
    """The held-out segments simulated with the fitted parameters: only their start states
    are fitted (four numbers against the whole segment). RMS error per channel (rad,
    rad/s) and as a multiple of the noise (1: at the noise level)."""
    if not problem.validation:
        return None
    result = solve(problem, xp, problem.validation, with_parameters=False, deadline=deadline)
    runs = problem.simulate(xp, result["states"], problem.validation)
    errors = np.vstack([run - problem.measured(g) for run, g in zip(runs, problem.validation)])
    sigma = np.vstack([np.broadcast_to(problem.sigma[g.recording], (g.stop - g.start, 4))
                       for g in problem.validation])
    rms = np.sqrt(np.mean(errors ** 2, axis=0))
    return {"rms": rms.tolist(), "noise_multiple": np.sqrt(np.mean((errors / sigma) ** 2,
                                                                   axis=0)).tolist(),
            "seconds": sum((g.stop - g.start - 1) * problem.recordings[g.recording].dt
                           for g in problem.validation),
            "states": result["states"], "runs": runs}
