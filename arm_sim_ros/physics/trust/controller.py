"""The step-size controller of the tolerance: how many equal sub-steps a step takes next.

A PI controller on the sub-step (Gustafsson; Hairer & Wanner II.4, as scipy's RK45): the
local error of a step of n sub-steps goes as n^-p, so with r = scaled error / (SAFETY x
tolerance x h), n' = n r^(KI/p) (r / r_prev)^(KP/p); growth of the sub-step bounded by
MAX_GROWTH per check, its shrink by MAX_SHRINK; a step that misses the tolerance is taken
again at the count it asks for (retake).
"""
from __future__ import annotations

from math import ceil, isfinite

from .shadow import LOST

SAFETY = 0.5              # counts aim at half the tolerance: fewer retaken steps
KI, KP = 0.7, 0.4         # PI gains on ln(error) (Hairer & Wanner's 0.7/k, 0.4/k)
MAX_GROWTH = 2.0          # a sub-step grows at most 2x per check ...
MAX_SHRINK = 10.0         # ... and shrinks at most 10x per retake
KEEP = 0.9                # fewer sub-steps only when the controller asks for < 90 %


def proposed(n: int, ratio: float, previous: float, order: int, floor: int, cap: int) -> int:
    """The sub-steps the controller asks for after a step of n sub-steps measured at
    `ratio` = scaled error / (SAFETY tolerance h) (`previous`: the check before)."""
    if not isfinite(ratio):
        return min(cap, max(floor, ceil(n * MAX_SHRINK)))
    ratio, previous = max(ratio, 1e-12), max(previous, 1e-12)
    factor = ratio ** (KI / order) * (ratio / previous) ** (KP / order)
    wanted = n * min(MAX_SHRINK, max(1.0 / MAX_GROWTH, factor))
    if wanted < n and wanted > KEEP * n:
        return n
    return max(floor, min(cap, ceil(wanted - 1e-9)))


def retake(n: int, ratio: float, order: int, cap: int) -> int:
    """The count a step that missed the tolerance is taken again at: where its error
    (as n^-p) meets SAFETY x the tolerance, at least one more, at most the cap."""
    wanted = n * min(MAX_SHRINK, ratio ** (1.0 / order)) if isfinite(ratio) else n * MAX_SHRINK
    return min(cap, max(n + 1, ceil(wanted - 1e-9)))


class Control:
    """One sub-step count under the controller: its floor, its ceiling, its last ratio."""

    def __init__(self, floor: int, cap: int):
        self.floor, self.cap = floor, max(floor, cap)
        self.n, self.previous = floor, 1.0

    def ask(self, ratio: float, order: int) -> int:
        """The count for the next steps after a step measured at `ratio`. At the floor, a
        step that met the tolerance asks for nothing more (plain steps stay plain: the
        explainer's figures bit for bit); above it the count follows the error both ways."""
        previous, self.previous = self.previous, ratio if isfinite(ratio) else self.previous
        if self.n <= self.floor and ratio * SAFETY <= 1.0:   # most checks: no pow to take
            return self.n
        return proposed(self.n, ratio, previous, order, self.floor, self.cap)


def said_count(books, wanted, first, h, reached=None, where="") -> None:
    """Say a new highest count once it is, and once that the cap could not meet it."""
    if books.emit is None:
        return
    if wanted >= books.cap and not books.capped and (reached is None or
                                                     reached > books.target(h)):
        books.capped = True
        books.emit("substepping", f"tolerance {books.tolerance:g} not met: local error "
                   f"{(reached if reached is not None else first) / h:.3g} per s (scaled) "
                   f"at the cap of {books.cap} sub-steps per step (max_substeps); the run "
                   "goes on at the cap")
    elif wanted > books.most and wanted > 2 * max(1, books.most):
        books.most = wanted     # the tolerance at work, as it is built to: "substeps", info
        books.emit("substeps", f"local error {first / h:.3g} per s (scaled) for "
                   f"tolerance {books.tolerance:g} (aiming at half): each {h:g} s "
                   f"step{where} is taken as {wanted} sub-steps")


def said_unreachable(books, scaled, n, h) -> None:
    """Splitting a step n-fold left its error where it was (rounding, or an error that
    sub-steps do not reduce): the count stays there, said once."""
    books.free.cap = books.cap = max(books.base, n)
    if books.emit is not None and not books.capped:
        books.capped = True
        books.emit("substepping", f"tolerance {books.tolerance:g} cannot be reached: "
                   f"{n} sub-steps left the local error at {scaled / h:.3g} per s "
                   "(scaled), as fewer did (rounding, or an error sub-steps do not "
                   f"reduce); the run stays at {n} sub-steps per step")


def said_lost(books, index: int, h: float) -> None:
    """The shadow lost the motion in step `index` (or before): said once, when it is. Where
    every step met the tolerance the errors grew by the motion itself (chaos, as a double
    pendulum's): said in plain words as "unpredictable", information, not a fault; with
    no tolerance, or one not met at the cap, it is an "accuracy" warning."""
    if books.shadow.lost and not books.said_lost and books.emit is not None:
        books.said_lost = True
        at = f"{(index + 1) * h:.6g}"
        if books.tolerance and not books.capped:
            books.emit("unpredictable", f"past t = {at} s this motion is unpredictable: it "
                       "is chaotic, and errors far below the tolerance at each step have grown "
                       f"past {LOST:g} rad; the run goes on, but no longer follows the true "
                       "motion (the error estimate stops at that bound)")
            return
        books.emit("accuracy", f"the global error estimate passed {LOST:g} rad by t = {at} s: "
                   "the run no longer follows the true motion (a step too coarse for it, or "
                   "chaos); the estimate stops at that bound")
