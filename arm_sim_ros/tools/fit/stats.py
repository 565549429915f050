"""What a fit's optimum is worth: standard errors, correlations, what the data do not
excite, and the error on the held-out validation segment.

Covariance of the scaled unknowns (parameters and segment start states together) is
s² (JᵀJ)⁻¹ from the Jacobian J at the optimum, s² = Σr² / (m − n) the residual variance;
a parameter's standard error is its diagonal entry's root times its scale, the start
states marginalised out. A parameter whose column of J is (next to) zero does not move the
simulated trajectory at all, and a breakaway friction of a joint that never stuck acts
nowhere: the recording cannot identify them (Unidentified, exit code 1, one line). Nor can a
recording that moves nowhere beyond its noise identify anything: a still arm would pass the
verdict on it (white noise counts as all noise), so no value is told from another; it is
refused before the fit (check_motion).
"""
from __future__ import annotations

import numpy as np

from .bounds import CHANNELS, EXPLAINED
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


class Unidentified(Exception):
    """The recording cannot identify a free key: which, and why (exit code 1, one line)."""


def motion(recording, sigma) -> np.ndarray:
    """How far q1, q2, qd1, qd2 move, in units of their σ: the positions' spread about
    their mean, the velocities' RMS (a still arm's velocity is zero)."""
    spread = np.concatenate([np.std(recording.q, axis=0),
                             np.sqrt(np.mean(recording.qd ** 2, axis=0))])
    return spread / sigma


def check_motion(problem: Problem) -> None:
    """Unidentified where a recording moves on no channel beyond EXPLAINED x its σ: a still
    arm would pass the verdict there, so the recording cannot tell one value of a key from
    another (white noise, whose 4th differences are as large as it, or a still arm)."""
    keys = ", ".join(p.key for p in problem.free)
    for recording, sigma in zip(problem.recordings, problem.sigma):
        moves = motion(recording, sigma)
        if not moves.max() > EXPLAINED:
            raise Unidentified(
                f"{recording.source} cannot identify {keys}: nothing in it moves beyond its "
                f"noise ({', '.join(CHANNELS)} vary by "
                f"{', '.join(f'{m:.3g}' for m in moves)} x the noise their 4th differences "
                "show: white noise or a still arm), so every value fits it as well; record a "
                "motion (arm-sim excite)")


def unidentified(problem: Problem, moved, runs, names) -> dict[int, str]:
    """{index: 'key (why)'} of each free key the fitted simulation shows nothing of: its
    motion does not depend on the key, or the key is the breakaway friction of a joint that
    never stuck."""
    found = {}
    for i, p in enumerate(problem.free):
        joint = names[p.index] if p.index is not None else "either joint"
        if p.field == "friction" and p.name == "static" and not stuck(runs, p.index):
            found[i] = (f"{p.key} (the {joint} never stuck: record motions that stop and "
                        "start again)")
        elif not moved[i]:
            found[i] = f"{p.key} (the simulated motion does not depend on it)"
    return found


def warnings_for(problem: Problem, values, se, correlation, moved, chi2: float) -> list[str]:
    """One line per parameter the recording barely identifies, per pair it cannot tell
    apart, and one if the best fit still misses the recording by more than its noise."""
    lines = []
    if chi2 > MISFIT:
        lines.append(f"the fitted simulation misses the recording by {chi2 ** 0.5:.3g} x its "
                     "noise (RMS): the base scene lacks something the arm has; free more keys")
    for i, p in enumerate(problem.free):
        if moved[i] and not se[i] <= LOOSE * max(abs(values[i]), p.typical * 1e-3):
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
