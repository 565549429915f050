"""How far each step is from the exact flow, and the equal sub-steps that keep it under a
tolerance.

Estimator (chosen by measurement, benchmarks/bench_tolerance.py): Richardson step
doubling on a schedule. Every CHECK_EVERY-th step, the step's first sub-step of size hs is
also taken as two halves; the difference, times 2^p / (2^p - 1), estimates the sub-step's
local error (p = the tableau's order); the step's estimate is n times that (n equal
sub-steps), carried to the steps until the next check. The step itself is untouched (bit
for bit the plain step); a check costs 8 more evaluations, 2/CHECK_EVERY of a step on
average. The alternative measured was RK4's FSAL embedded third-order companion,
h/6 (k4 - f(y_{n+1})): it estimates the third-order solution's error, not RK4's, and its
sum over the presets was 32-116x the true global error, where doubling's is 5-8x.

`error_estimate` is the latest step's local error (max over q, qd of |e|, rad and rad/s);
`accumulated_error` sums them: a bound on the global error while errors do not grow
along the motion (it is not one for chaotic motion, where neighbouring paths separate).

Tolerance: a step whose scaled local error max |e_i| / (1 + |y_i|) exceeds tolerance x h
(per simulated second, so the bound on the drift does not depend on h) is split into the
fewest equal sub-steps n' that bring it under: the error of n equal sub-steps falls as
n^-p, so n' = ceil(n (err / (SAFETY tolerance h))^(1/p)); a check that finds its own
step too coarse measures again at n' (until it passes) and takes the step that way. The count is kept until reset (it never shrinks).
"""
from __future__ import annotations

from math import ceil, isfinite

from . import stability

CHECK_EVERY = 16          # steps between doubling checks (a check: 8 evaluations)
SPLIT_CHECK_EVERY = 4     # ... while the tolerance splits steps (8 vs 4 n evaluations)
SAFETY = 0.5              # new counts aim at half the tolerance: fewer retaken steps
MAX_SUBSTEPS = 10_000     # the most a tolerance may ask of one step
# Per simulated second, scaled error max |e_i| / (1 + |y_i|); 0 = off (estimate only).
# 2e-3 keeps a 100 rad/s spin within 1e-6 relative energy drift over 5 s at h = 1 ms and
# 10 ms and every explainer figure bit for bit, but also re-splits stiff scenes the
# stability plan already splits and moving_frozen_gravity after 1.5 s: not yet default.
SPIN_TOLERANCE = 2e-3
DEFAULT_TOLERANCE = 0.0


class Accuracy:
    """advance(f, y, h) for the simulator: the planned equal sub-steps, error-checked."""

    def __init__(self, step, order: int, tolerance: float, width: int, substeps: int = 1,
                 emit=None):
        self.step, self.order, self.tolerance, self.width = step, order, tolerance, width
        self.factor = 2.0 ** order / (2.0 ** order - 1.0)
        self.base = substeps          # the stability plan's count: never fewer
        self.emit = emit              # emit(kind, message): a count above any before
        self.most = substeps
        self.reset()

    def reset(self) -> None:
        self.substeps = self.base     # sub-steps the next step takes
        self.error_estimate = 0.0     # the latest step's local error estimate
        self.accumulated_error = 0.0  # their sum since reset
        self.scaled = 0.0             # the latest step's scaled error per second
        self.steps = 0
        self.taken = 0                # sub-steps run in split steps since reset

    def _run(self, f, y, h, n, start=0):
        hs = h / n
        for _ in range(start, n):
            y = self.step(f, y, hs)
        return y

    def _measure(self, f, y, hs):
        """(first sub-step, its local error, its scaled error) by step doubling."""
        first = self.step(f, y, hs)
        halves = self.step(f, self.step(f, y, 0.5 * hs), 0.5 * hs)
        error = scaled = 0.0
        for a, b in zip(first[:self.width], halves[:self.width]):
            e = abs(a - b) * self.factor
            error, scaled = max(error, e), max(scaled, e / (1.0 + abs(a)))
        return first, error, scaled

    def needed(self, n: int, scaled: float, h: float) -> int:
        """Sub-steps for which a step measured at `scaled` with n sub-steps meets the
        tolerance; never fewer than n: the count a run once needed is kept until reset
        (the error of a spinning arm peaks for a few steps each swing of the elbow, and a
        check between peaks must not undo what the peaks need)."""
        limit = self.tolerance * h
        if not isfinite(scaled) or scaled <= limit or not self.tolerance:
            return n
        return min(MAX_SUBSTEPS, ceil(n * (scaled / (SAFETY * limit)) ** (1.0 / self.order)))

    def advance(self, f, y, h):
        n = self.substeps
        if n == 1 and self.base == 1 and self.steps % CHECK_EVERY:   # the common plain step
            self.accumulated_error += self.error_estimate
            self.steps += 1
            return self.step(f, y, h)
        if self.steps % (CHECK_EVERY if n == self.base else SPLIT_CHECK_EVERY):
            y1 = self._run(f, y, h, n)
        else:
            first, error, scaled = self._measure(f, y, h / n)
            wanted = self.needed(n, n * scaled, h)
            measured = n * scaled / h
            while wanted > n:        # too coarse: measure again at the count it needs
                n = wanted
                first, error, scaled = self._measure(f, y, h / n)
                wanted = self.needed(n, n * scaled, h)
            self.error_estimate, self.scaled = n * error, n * scaled
            y1 = self._run(f, first, h, n, 1)
            self.substeps = wanted
            if wanted > self.most and self.emit is not None:
                self.most = wanted
                self.emit("substepping", f"local error {measured:.3g} per s (scaled) "
                          f"exceeds tolerance {self.tolerance:g}: each {h:g} s step is taken "
                          f"as {wanted} sub-steps")
        self.accumulated_error += self.error_estimate
        self.steps += 1
        if n > 1:
            self.taken += n
        return y1


class Embedded:
    """The same books for an embedded pair (dopri5): the step reports its own estimate
    (the sum over its accepted sub-steps); rtol and atol, not `tolerance`, control it."""

    def __init__(self, step, advance):
        self.step, self.advance_by, self.substeps = step, advance, 1
        self.reset()

    def reset(self) -> None:
        self.error_estimate = self.accumulated_error = 0.0
        self.taken = self.steps = 0

    def advance(self, f, y, h):
        y1 = self.advance_by(f, y, h)
        self.error_estimate = self.step.last_error
        self.accumulated_error += self.error_estimate
        self.steps += 1
        return y1


class Unchecked:
    """No estimate (NaN): steps that switch modes at located events (events.py), or that
    the stability plan refuses. `taken` None: the simulator counts sub-steps itself."""

    error_estimate = accumulated_error = float("nan")
    taken = None

    def __init__(self, advance=None):
        self.advance = advance

    def reset(self) -> None:
        pass


UNCHECKED = Unchecked()


def plan(tableau, step, advance, substeps: int, tolerance: float, width: int, emit=None):
    """The error books, whose `advance` the simulator takes: the embedded pair's own
    estimate, or checked equal sub-steps (over the stability plan's) of a fixed-step method."""
    if getattr(tableau, "adaptive", False):
        return Embedded(step, advance)
    if substeps > stability.MAX_SUBSTEPS:   # the stability plan refuses: keep its refusal
        return Unchecked(advance)
    return Accuracy(step, tableau.order, tolerance, width, substeps, emit)
