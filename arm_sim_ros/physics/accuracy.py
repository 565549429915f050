"""How far each step is from the exact flow, and the sub-steps that keep it under a
tolerance: an error estimate on a schedule and a step-size controller that moves both ways.

Estimator (measured: benchmarks/bench_tolerance.py, test/test_error_estimate.py): Richardson
step doubling on a schedule. A check takes the step (n equal sub-steps, bit for bit the
plain step) and again as 2n half sub-steps; the difference x 2^p / (2^p - 1) is the step's
local error at its end (p = the tableau's order). Measured at the end, not as n x the
first sub-step: a stiff mode the stability plan's sub-steps damp out within the step has
decayed by then. The estimate is carried to the steps until the next check, so an
unchecked step is the compiled step called by the simulator directly, nothing else.

Schedule: every CHECK_EVERY-th step; every RELAXED_EVERY-th while the estimate is under
RELAXED x the tolerance at the planned count; a check costs 2 steps' evaluations.
Switching scenes (events.py): every step in which a switch is located, and every step
that starts with a compliant limit engaged, is checked; each smooth piece up to a switch
is doubled and the pieces' errors are summed.

Controller: the sub-step size h / n follows the error both ways, as a PI step-size
controller does (Gustafsson; Hairer & Wanner II.4, scipy's RK45): the local error of a
step of n sub-steps goes as n^-p, so with r = scaled error / (SAFETY x tolerance x h),
n' = n r^(KI/p) (r / r_prev)^(KP/p), growth of the sub-step bounded by MAX_GROWTH per check
and its shrink by MAX_SHRINK; a check that misses the tolerance (r > 1 / SAFETY) is taken
again at the count it asks for. Tick boundaries stay exact: a step is always n equal
sub-steps. The stability plan's count is a floor, never a ratchet; `max_substeps` is the
ceiling: past it the step is taken at the cap and the run says once what error it reached.
On switching scenes the sub-steps of a compliant contact and of free motion are
controlled apart (a contact needs fine steps, the flight between contacts does not).

`error_estimate` is the latest check's local error (max over q, qd of |e|, rad and rad/s);
`accumulated_error` sums them over the steps (carried steps at the mean of the checks
either side; until then at half the latest, so the sum never goes down).

Tolerance: the scaled error max(|e_q|, |e_qd| / (1 + |qd|)) per step is held under
tolerance x h (per simulated second, so the bound on the drift does not depend on h;
angles unscaled: they are unwrapped, their size says nothing). 0 turns the controller off
(estimate only). Default (DEFAULT_TOLERANCE = 5e-5 per s): a 100 rad/s spin needs <= 1e-4
for a relative energy drift < 1e-6 over 5 s at h = 10 ms, and the explainer's figures are
left bit for bit down to 3e-5.
"""
from __future__ import annotations

from math import ceil, isfinite

from . import stability

CHECK_EVERY = 16          # steps between doubling checks (a check: 2 steps' evaluations)
RELAXED_EVERY = 32        # ... while the estimate is under RELAXED x the tolerance at the
RELAXED = 1.0 / 16.0      # planned count (a step twice as long would still meet it: 2^4)
SAFETY = 0.5              # counts aim at half the tolerance: fewer retaken steps
KI, KP = 0.7, 0.4         # PI gains on ln(error) (Hairer & Wanner's 0.7/k, 0.4/k)
MAX_GROWTH = 2.0          # a sub-step grows at most 2x per check ...
MAX_SHRINK = 10.0         # ... and shrinks at most 10x per retake
KEEP = 0.9                # fewer sub-steps only when the controller asks for < 90 %
DEFAULT_MAX_SUBSTEPS = 1000   # the tolerance's ceiling per step (scene key max_substeps)
MAX_SUBSTEPS = stability.MAX_SUBSTEPS   # what a scene may set it to
# Per simulated second, scaled error (see above); 0 = off (estimate only).
DEFAULT_TOLERANCE = 5e-5


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
        wanted = proposed(self.n, ratio, self.previous, order, self.floor, self.cap)
        self.previous = ratio if isfinite(ratio) else self.previous
        if self.n <= self.floor and ratio * SAFETY <= 1.0:
            return self.n
        return wanted


class Accuracy:
    """The error books of a fixed-step method. The simulator takes `plain(f, y, h)` (the
    planned step, nothing else) while its step index is below `due`, else `check(f, y, h)`;
    the estimate is carried between checks, so the sums are counted when asked for."""

    def __init__(self, step, order: int, tolerance: float, width: int, substeps: int = 1,
                 emit=None, clock=None, stepper=None, cap: int = DEFAULT_MAX_SUBSTEPS):
        self.step, self.order, self.tolerance, self.width = step, order, tolerance, width
        self.factor = 2.0 ** order / (2.0 ** order - 1.0)
        self.base = substeps          # the stability plan's count: never fewer
        self.cap = max(substeps, cap)  # the tolerance's ceiling
        self.emit = emit              # emit(kind, message)
        self.clock = clock            # the simulator's step index (the step being taken)
        self.stepper = stepper        # events.Switching: it steps, pieces are estimated
        if stepper is not None:       # ... and a step with a switch or a contact always
            stepper.checked = self.check
        self.reset()

    def reset(self) -> None:
        self.error_estimate = 0.0     # the latest check's local error estimate
        self.since = self.due = 0     # step index of the latest check; of the next
        self.booked = 0.0             # Σ error_estimate over the steps before `since`
        self.booked_taken = 0         # sub-steps run in split steps before `since`
        self.free = Control(self.base, self.cap)
        self.contact = Control(0, self.cap)      # engaged pieces (switching stepper)
        self.most = self.base         # the largest count said so far
        self.capped = False           # said once: the tolerance was not met at the cap
        self.substeps = -1
        self.use(self.base)
        if self.stepper is not None:
            self.stepper.contact_substeps = 0

    def use(self, n: int) -> None:
        """Take n equal sub-steps from now on."""
        self.free.n = n
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

    def ratio(self, scaled: float, h: float) -> float:
        return scaled / (SAFETY * self.tolerance * h)

    def check(self, f, y, h):
        """The step, measured; a miss of the tolerance is taken again at the count the
        controller asks for (until it passes or the cap is reached)."""
        index, n = self.clock(), self.substeps
        if self.stepper is not None:
            return self.switching(f, y, h, index, n)
        y1, error, scaled = self.measure(f, y, h, n)
        first, wanted = scaled, n
        if self.tolerance:
            wanted = self.free.ask(self.ratio(scaled, h), self.order)
            while scaled > self.tolerance * h and n < self.cap:      # a miss: retaken
                n = self.free.n = retake(n, self.ratio(scaled, h), self.order, self.cap)
                y1, error, scaled = self.measure(f, y, h, n)
                wanted = self.free.ask(self.ratio(scaled, h), self.order)
        self.book(index, error, scaled, n, h, first, wanted)
        return y1

    def switching(self, f, y, h, index, n):
        """A step of a switching scene: every sub-step (each smooth piece between located
        switches) doubled, errors summed, free flight and compliant contact apart; the
        counts the controller asks for apply from the next step on (this one's switches
        are already booked)."""
        sums = {False: [0.0, 0.0, 0], True: [0.0, 0.0, 0]}    # error, scaled, pieces
        stepper = self.stepper

        def piece(rhs, y0, dt, full):
            error, scaled = self.doubled(rhs, y0, dt, full)
            part = sums[bool(stepper.mode[2] or stepper.mode[3])]
            part[0] += error
            part[1] += scaled
            part[2] += 1

        y1 = stepper.advance(f, y, h, piece)
        error = sums[False][0] + sums[True][0]
        scaled = sums[False][1] + sums[True][1]
        wanted = n
        if self.tolerance:
            if sums[False][2]:
                wanted = self.free.ask(self.ratio(sums[False][1], h), self.order)
            if sums[True][2]:                # compliant contact: its own count
                self.contact.floor = stepper.contact_floor(h)
                self.contact.n = stepper.substeps_for(h, True)
                stepper.contact_substeps = self.contact.ask(self.ratio(sums[True][1], h),
                                                            self.order)
                self.told(stepper.contact_substeps, sums[True][1], h, sums[True][1],
                          " while a compliant limit is engaged")
        self.book(index, error, scaled, n, h, scaled, wanted)
        return y1

    def book(self, index, error, scaled, n, h, first, wanted):
        """Close the books up to step `index` (which took n sub-steps and made `error`) and
        carry this estimate from it on (predicted at the new count)."""
        carried = index - self.since            # steps that carried the latest estimate
        # ... booked at the mean of the checks either side (the error between them moved)
        self.booked += 0.5 * (self.error_estimate + error) * carried + error
        self.booked_taken += (self.substeps * carried if self.substeps > 1 else 0) + (
            n if n > 1 else 0)
        self.since = index + 1
        self.error_estimate = error * (n / wanted) ** self.order if wanted != n else error
        self.use(wanted)
        relax = (wanted <= self.base and self.tolerance
                 and scaled < RELAXED * self.tolerance * h)
        self.due = index + (RELAXED_EVERY if relax else CHECK_EVERY)
        if self.tolerance:
            self.told(wanted, first, h, scaled)

    def told(self, wanted, first, h, reached=None, where="") -> None:
        """Say a new highest count once it is, and once that the cap could not meet it."""
        if self.emit is None:
            return
        if wanted >= self.cap and not self.capped and (reached is None or
                                                       reached > self.tolerance * h):
            self.capped = True
            self.emit("substepping", f"tolerance {self.tolerance:g} not met: local error "
                      f"{(reached if reached is not None else first) / h:.3g} per s (scaled) "
                      f"at the cap of {self.cap} sub-steps per step (max_substeps); the run "
                      "goes on at the cap")
        elif wanted > self.most and wanted > 2 * max(1, self.most):
            self.most = wanted
            self.emit("substepping", f"local error {first / h:.3g} per s (scaled) for "
                      f"tolerance {self.tolerance:g} (aiming at half): each {h:g} s "
                      f"step{where} is taken as {wanted} sub-steps")


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
         clock=None, stepper=None, previous=None, cap: int = DEFAULT_MAX_SUBSTEPS):
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
        books = Accuracy(step, tableau.order, tolerance, width, substeps, emit, clock, stepper,
                         cap)
    if previous is not None:        # go on from here: the sums so far, a check at once
        books.carry(previous, clock())
    return books
