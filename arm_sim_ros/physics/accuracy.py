"""How far each step is from the exact flow, and the equal sub-steps that keep it under a
tolerance.

Estimator (measured: benchmarks/bench_tolerance.py, test/test_error_estimate.py): Richardson
step doubling on a schedule. A check takes the step (n equal sub-steps, bit for bit the
plain step) and again as 2n half sub-steps; the difference x 2^p / (2^p - 1) is the step's
local error at its end (p = the tableau's order). Measured at the end, not as n x the
first sub-step: a stiff mode the stability plan's sub-steps damp out within the step
(damping 500 at h = 50 ms: 377 sub-steps, true error 3e-9) made the first-sub-step
estimate 1e9 times too large and split such steps 4-10x more for no gain. The estimate is
carried to the steps until the next check; the books are closed lazily at each check
(carried steps at the mean of the checks either side; until then at half the latest, the
least that mean can be, so the sum never goes down), so an unchecked step is the
compiled step called by the simulator directly, nothing else.

Schedule: every CHECK_EVERY-th step; every RELAXED_EVERY-th while the estimate is under
RELAXED x the tolerance; a check costs 2 steps' evaluations. Release, h = 10 ms: plain
4.0 us/step, estimate only +18 %, default tolerance +10 % (was +23 % through a wrapper).
Sparser checks cost honesty: at 64 steps the sums fell to 0.11-0.24x of the true error.

Switching scenes (events.py): the same doubling, sub-step by sub-step: each smooth piece
up to a located switch is doubled and the pieces' errors summed. Steps without a switch
follow the schedule; a step that starts with a compliant limit engaged is always
estimated, and so is a step with a located switch when steps are not split (the switch is
seen in the plain step's fast path, events.py; split steps are estimated on the schedule):
they are short and where the error is made. A count the tolerance raises there applies
from the next step (the step's switches are already booked).

`error_estimate` is the latest check's local error (max over q, qd of |e|, rad and rad/s);
`accumulated_error` sums them over the steps: a bound on the global error while errors do
not grow along the motion (not for chaotic motion, nor through a hard impact's impulse).

Tolerance: a check whose scaled error max(|e_q|, |e_qd| / (1 + |qd|)) exceeds tolerance x h
(per simulated second, so the bound on the drift does not depend on h; angles unscaled:
they are unwrapped, their size says nothing) re-measures with the fewest equal sub-steps
n' = ceil(n (err / (SAFETY tolerance h))^(1/p)) until it passes, takes the step that way and
keeps the count until reset (the error of a spinning arm peaks each swing of the elbow).

Default (DEFAULT_TOLERANCE = 5e-5 per s), measured: a 100 rad/s spin (gravity off, elbow
0.5 rad) needs <= 1e-4 for relative energy drift < 1e-6 over 5 s at h = 10 ms (1e-4: 6.5e-7;
5e-5: 2.8e-7; at 1 ms 6e-9); explainer figures are left bit for bit down to 3e-5 (1e-5
splits release at h = 5 ms): 5e-5 sits between with ~2-4x margin either side. Their steps
are accurate on the schedule, not at every instant: checked every step, release at 10 ms
peaks at 1.4e-3 per s for a few steps as the elbow whips, which no check falls on; a
tolerance is a budget for sustained error, sampled. It also asks for what it says
elsewhere: mildly stiff steps the plan leaves under-resolved (springs k = 1e6 at 1 ms: true
error 24 rad -> 4e-5 at 171 sub-steps; damping 50 kicked: 1.7e-4 -> 1.9e-7 at 41 vs 8),
springs_oscillation and stick_slip from the start (2 sub-steps), payload_release from 0.6 s,
moving_frozen_gravity from 1.8 s, release from 3 s. 0 turns it off (estimate only).
"""
from __future__ import annotations

from math import ceil, isfinite

from . import stability

CHECK_EVERY = 16          # steps between doubling checks (a check: 2 steps' evaluations)
RELAXED_EVERY = 32        # ... while the estimate is under RELAXED x the tolerance (and
                          # the tolerance does not split steps: a check is 2n sub-steps)
RELAXED = 1.0 / 16.0      # (a step twice as long would still meet it: 2^p = 16 for RK4)
SAFETY = 0.5              # new counts aim at half the tolerance: fewer retaken steps
MAX_SUBSTEPS = 10_000     # the most a tolerance may ask of one step
# Per simulated second, scaled error (see above); 0 = off (estimate only).
DEFAULT_TOLERANCE = 5e-5


class Accuracy:
    """The error books of a fixed-step method. The simulator takes `plain(f, y, h)` (the
    planned step, nothing else) while its step index is below `due`, else `check(f, y, h)`;
    the estimate is carried between checks, so the sums are counted when asked for."""

    def __init__(self, step, order: int, tolerance: float, width: int, substeps: int = 1,
                 emit=None, clock=None, stepper=None):
        self.step, self.order, self.tolerance, self.width = step, order, tolerance, width
        self.factor = 2.0 ** order / (2.0 ** order - 1.0)
        self.base = substeps          # the stability plan's count: never fewer
        self.emit = emit              # emit(kind, message): a count above any before
        self.clock = clock            # the simulator's step index (the step being taken)
        self.stepper = stepper        # events.Switching: it steps, pieces are estimated
        if stepper is not None:       # ... and a step with a switch or a contact always
            stepper.checked = self.check
        self.most = substeps
        self.reset()

    def reset(self) -> None:
        self.error_estimate = 0.0     # the latest check's local error estimate
        self.since = self.due = 0     # step index of the latest check; of the next
        self.booked = 0.0             # Σ error_estimate over the steps before `since`
        self.booked_taken = 0         # sub-steps run in split steps before `since`
        self.substeps = -1
        self.use(self.base)

    def use(self, n: int) -> None:
        """Take n equal sub-steps from now on."""
        if n != self.substeps:
            self.substeps = n
            if self.stepper is not None:
                self.stepper.substeps = n
                self.plain = self.stepper.advance
            else:
                self.plain = stability.substepping(self.step, n)

    def carry(self, previous, steps: int) -> None:
        """Go on from the books `previous` after `steps` steps: their sums (closed: no later
        check of theirs re-counts their latest steps), a check at once."""
        self.booked = previous.accumulated(steps, closing=True)
        self.booked_taken = previous.taken(steps) or 0
        self.since = self.due = steps

    def accumulated(self, steps: int, closing: bool = False) -> float:
        """Σ error_estimate over `steps` steps since reset. Steps since the latest check count
        at half its estimate until the next check books them at the mean of the two (never
        less: estimates are >= 0), so the sum never goes down; `closing` (no next check:
        the dynamics are rebuilt) at its estimate."""
        share = 1.0 if closing else 0.5
        return self.booked + share * self.error_estimate * (steps - self.since)

    def taken(self, steps: int) -> int:
        """Sub-steps run in split steps over `steps` steps since reset (0: plain steps),
        those the switching stepper adds (contacts, re-splits after a switch) included."""
        return self.booked_taken + (self.substeps * (steps - self.since)
                                    if self.substeps > 1 else 0) + (
            self.stepper.extra_substeps if self.stepper is not None else 0)

    def doubled(self, f, y, h, full, n=1) -> tuple[float, float]:
        """(local error, scaled error) of y -> full, n equal sub-steps over h, by taking it
        again as 2n half sub-steps (Richardson: the difference x 2^p / (2^p - 1)): the
        error at the step's end, where a stiff mode's early sub-step errors have decayed."""
        hs = 0.5 * h / n
        for _ in range(2 * n):
            y = self.step(f, y, hs)
        errors = [abs(a - b) * self.factor for a, b in zip(full[:self.width], y)]
        # angles are unwrapped: their size says nothing of the error they can take
        scaled = max(max(errors[:2]), *(e / (1.0 + abs(a)) for e, a in zip(errors[2:], full[2:])))
        return max(errors), scaled

    def measure(self, f, y, h, n):
        """(the step as n sub-steps, its error, its scaled error)."""
        full = self.plain(f, y, h) if n == self.substeps else stability.substepping(
            self.step, n)(f, y, h)
        return (full, *self.doubled(f, y, h, full, n))

    def needed(self, n: int, scaled: float, h: float) -> int:
        """Sub-steps for which a step measured at `scaled` with n sub-steps meets the
        tolerance; never fewer than n: the count a run once needed is kept until reset
        (the error of a spinning arm peaks for a few steps each swing of the elbow, and a
        check between peaks must not undo what the peaks need)."""
        limit = self.tolerance * h
        if not isfinite(scaled) or scaled <= limit or not self.tolerance:
            return n
        return min(MAX_SUBSTEPS, ceil(n * (scaled / (SAFETY * limit)) ** (1.0 / self.order)))

    def check(self, f, y, h):
        """The step, measured; too coarse for the tolerance: measured again at the count it
        needs (until it passes) and taken that way."""
        index, n = self.clock(), self.substeps
        if self.stepper is not None:
            return self.switching(f, y, h, index, n)
        y1, error, scaled = self.measure(f, y, h, n)
        wanted = self.needed(n, scaled, h)
        first = scaled
        while wanted > n:
            n = wanted
            y1, error, scaled = self.measure(f, y, h, n)
            wanted = self.needed(n, scaled, h)
        self.book(index, error, scaled, n, h, first)
        return y1

    def switching(self, f, y, h, index, n):
        """A step of a switching scene: every sub-step (each smooth piece between located
        switches) doubled, errors summed; a count the tolerance raises applies from the
        next step on (this one's switches are already booked)."""
        sums = [0.0, 0.0]

        def piece(rhs, y0, dt, full):
            error, scaled = self.doubled(rhs, y0, dt, full)
            sums[0] += error
            sums[1] += scaled

        y1 = self.stepper.advance(f, y, h, piece)
        self.book(index, sums[0], sums[1], n, h, sums[1], self.needed(n, sums[1], h))
        return y1

    def book(self, index, error, scaled, n, h, first, wanted=None):
        """Close the books up to step `index` (which took n sub-steps and made `error`) and
        carry this estimate from it on."""
        carried = index - self.since            # steps that carried the latest estimate
        # ... booked at the mean of the checks either side (the error between them moved)
        self.booked += 0.5 * (self.error_estimate + error) * carried + error
        self.booked_taken += (self.substeps * carried if self.substeps > 1 else 0) + (
            n if n > 1 else 0)
        self.since, self.error_estimate = index + 1, error
        wanted = n if wanted is None else wanted
        self.use(wanted)
        relax = (wanted <= self.base and self.tolerance      # never while the tolerance splits
                 and scaled < RELAXED * self.tolerance * h)
        self.due = index + (RELAXED_EVERY if relax else CHECK_EVERY)
        if wanted > self.most and self.emit is not None:
            self.most = wanted
            self.emit("substepping", f"local error {first / h:.3g} per s (scaled) "
                      f"exceeds tolerance {self.tolerance:g}: each {h:g} s step is taken "
                      f"as {wanted} sub-steps")


class Embedded:
    """The same books for an embedded pair (dopri5): the step reports its own estimate
    (the sum over its accepted sub-steps); rtol and atol, not `tolerance`, control it."""

    due = 0                     # every step is its own check

    def __init__(self, step):
        self.step, self.substeps = step, 1
        self.plain = self.check = self.advance
        self.reset()

    def reset(self) -> None:
        self.error_estimate = self.accumulated_error = 0.0

    def carry(self, previous, steps: int) -> None:
        """Go on from the books `previous` after `steps` steps: their sum."""
        self.accumulated_error = previous.accumulated(steps, closing=True)

    def accumulated(self, steps: int, closing: bool = False) -> float:
        return self.accumulated_error

    def taken(self, steps: int) -> int:
        return 0

    def advance(self, f, y, h):
        y1 = self.step(f, y, h)
        self.error_estimate = self.step.last_error
        self.accumulated_error += self.error_estimate
        return y1


class Unchecked:
    """No estimate (NaN): steps the stability plan refuses, and dopri5 on a scene that switches
    modes (`stepper`)."""

    error_estimate = float("nan")
    due = 0

    def __init__(self, advance, substeps: int, stepper=None):
        self.check = self.plain = advance
        self.substeps, self.stepper = substeps, stepper

    def reset(self) -> None:
        pass

    def accumulated(self, steps: int, closing: bool = False) -> float:
        return self.error_estimate

    def taken(self, steps: int) -> int:
        return (steps * self.substeps if self.substeps > 1 else 0) + (
            self.stepper.extra_substeps if self.stepper is not None else 0)


def plan(tableau, step, substeps: int, tolerance: float, width: int, emit=None,
         clock=None, stepper=None, previous=None):
    """The error books, with the step they take (`step` as the stability plan's `substeps`
    equal sub-steps): the embedded pair's own estimate, or checked equal sub-steps (over the
    stability plan's) of a fixed-step method, switched at events by `stepper` if any.
    `previous`: the books so far (a payload grasped rebuilds the dynamics mid-run)."""
    if getattr(tableau, "adaptive", False) and stepper is not None:
        # dopri5 between located switches: its pieces' own estimates are not summed (NaN);
        # without the switches its error control would chase the kink forever.
        return Unchecked(stepper.advance, substeps, stepper)
    if getattr(tableau, "adaptive", False):
        books = Embedded(step)        # (an adaptive method plans no sub-steps)
    elif substeps > stability.MAX_SUBSTEPS:   # the stability plan refuses: keep its refusal
        return Unchecked(stability.substepping(step, substeps), substeps)
    else:
        books = Accuracy(step, tableau.order, tolerance, width, substeps, emit, clock, stepper)
    if previous is not None:        # go on from here: the sums so far, a check at once
        books.carry(previous, clock())
    return books
