"""What every `arm-sim fit` ends within, why it stopped, and its verdict: whether the fitted
model explains the recording.

Bounds, each stated in the output:
- steps per sample (MAX_STEPS_PER_SAMPLE): a recording whose sample interval takes more of
  the scene's steps (a --step far finer than the samples), or whose samples are more than
  MAX_SAMPLE_INTERVAL apart (time stamps in ms or ns read as seconds), is refused before
  anything runs; a parameter set whose replay would take more
  (the stability plan's sub-steps, as damping grows) is refused as a scene the values
  break is, so the search turns back;
- the least-squares problem: segments of at least MIN_SEGMENT_SAMPLES samples, and a
  Jacobian within MAX_JACOBIAN_BYTES (it is dense: residuals x unknowns, each segment's
  start state four unknowns), refused before anything runs with its size;
- evaluations per start (--max-evaluations) and wall time (--max-seconds): a start stops at
  the first with its best point, and a Dask cluster that returns nothing in the wall time
  (no workers, a server that never answers) is given up.

Verdict (`explains`): the fitted simulation stays within EXPLAINED x the noise (RMS, per
channel) on the held-out validation and over the training (χ² per residual within
EXPLAINED²); a fit that converged to a model that does not is exit code 3. The noise is
never taken below the replay's resolution (problem.noise_level: a fraction of what the
signal changes in a sample interval), and a recording that moves nowhere beyond EXPLAINED x
its noise, which a still arm would pass, gets no verdict: it identifies nothing (stats.py).
"""
from __future__ import annotations

import time

import numpy as np

from ...usage import DONE, FAULT, UNEXPLAINED
from .data import FitError

MAX_STEPS_PER_SAMPLE = 1000     # simulation steps between two samples, sub-steps included
MAX_SAMPLE_INTERVAL = 1.0       # s: slower JointStates show no motion a fit could identify
MIN_SEGMENT_SAMPLES = 10        # samples a multiple-shooting segment holds at least
MAX_JACOBIAN_BYTES = 2 ** 30    # the dense Jacobian of the training problem
DEFAULT_SECONDS = 900.0         # wall time of a whole fit (--max-seconds)
EXPLAINED = 2.0                 # RMS error in units of the noise, every channel
# exit codes (usage.py): the model explains the recording, a bound reached before it
# converged or a key the recording cannot identify, converged but the model misses it
EXPLAINED_CODE, STOPPED_CODE, UNEXPLAINED_CODE = DONE, FAULT, UNEXPLAINED
UNIDENTIFIED_CODE = FAULT
CHANNELS = ("q1", "q2", "qd1", "qd2")


def check_sampling(recording, step_size: float) -> int:
    """Steps of `step_size` per sample interval of `recording`, or FitError past the bound
    (or samples further apart than MAX_SAMPLE_INTERVAL)."""
    if recording.dt > MAX_SAMPLE_INTERVAL:
        raise FitError(f"{recording.source}: samples {recording.dt:.6g} s apart, under "
                       f"{1 / MAX_SAMPLE_INTERVAL:g} Hz: time stamps in ms or ns? (a CSV's t "
                       "is in seconds; a bag's stamps are read as ROS stamps)")
    steps = max(1, int(np.ceil(recording.dt / step_size - 1e-9)))
    if steps > MAX_STEPS_PER_SAMPLE:
        raise FitError(
            f"{recording.source}: samples {recording.dt:.6g} s apart take {steps} steps of "
            f"{step_size:g} s; a fit replays at most {MAX_STEPS_PER_SAMPLE} per sample "
            "(time stamps in ms or ns? a CSV's t is in seconds; else a coarser --step)")
    return steps


def check_size(problem) -> None:
    """FitError before anything runs where the segments are too short or the problem too
    large to hold (its dense Jacobian)."""
    for g in problem.training + problem.validation:
        if g.stop - g.start < MIN_SEGMENT_SAMPLES:
            dt = problem.recordings[g.recording].dt
            raise FitError(f"--segment / --validation leave a segment of {g.stop - g.start} "
                           f"samples; a fit needs at least {MIN_SEGMENT_SAMPLES} "
                           f"({MIN_SEGMENT_SAMPLES * dt:.3g} s at {1 / dt:.4g} Hz)")
    rows = sum(4 * (g.stop - g.start) for g in problem.training)
    unknowns = problem.n_parameters + 4 * len(problem.training)
    size = 8 * rows * unknowns
    if size > MAX_JACOBIAN_BYTES:
        raise FitError(f"the fit would solve {rows:,} residuals for {unknowns:,} unknowns: "
                       f"its Jacobian takes {size / 2 ** 30:.3g} GiB, beyond "
                       f"{MAX_JACOBIAN_BYTES / 2 ** 30:g} GiB; fit a shorter stretch of the "
                       "recording (a few minutes at most) or longer --segment")


class Deadline:
    """The wall time a fit (and each of its starts) may take, from now."""

    def __init__(self, seconds: float):
        self.seconds, self.at = seconds, time.monotonic() + seconds

    def left(self) -> float:
        return max(0.0, self.at - time.monotonic())


def stopped(result: dict, max_evaluations: int, seconds: float) -> str:
    """Why a start stopped, in the bound's own words."""
    if result["status"] == -3:
        return f"the wall-time bound ({seconds:g} s, --max-seconds)"
    if result["status"] == 0:
        return f"the evaluation bound ({max_evaluations} per start, --max-evaluations)"
    return f"converged ({result['message'].rstrip('.')})"


def verdict(outcome: dict) -> dict:
    """Whether the fitted model explains the recording, the rule and the numbers it read."""
    training = outcome["training"]["chi2_per_residual"] ** 0.5
    validation = outcome["validation"]
    held = validation["noise_multiple"] if validation is not None else []
    worst = max([training, *held])
    where = "training" if worst == training else f"validation {CHANNELS[held.index(worst)]}"
    return {"explains": bool(worst <= EXPLAINED), "worst_noise_multiple": worst,
            "where": where,
            "rule": f"the fitted simulation within {EXPLAINED:g} x the noise (RMS; at least "
                    "the replay's resolution) on every channel of the held-out validation "
                    "and over the training"}


def bounds(args) -> dict:
    return {"evaluations_per_start": args.max_evaluations, "seconds": args.max_seconds,
            "steps_per_sample": MAX_STEPS_PER_SAMPLE}
