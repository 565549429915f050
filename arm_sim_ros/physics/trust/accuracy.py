"""How far each step is from the exact flow, how far the run is from the true motion, and
the sub-steps that keep each step under a tolerance.

Local error (benchmarks/bench_tolerance.py, test/physics/test_error_estimate.py): Richardson step
doubling on a schedule. A check takes the step (n equal sub-steps, bit for bit the plain
step) and again as 2n half sub-steps; the difference x 2^p / (2^p - 1) is the step's
local error at its end (where a stiff mode the plan's sub-steps damp has decayed), signed,
for every state. A split step (n > 1) is measured against other counts of its sub-steps
instead (compared): ceil(n/2) and ceil(n/3) coarser ones where those are as stable, else
ceil(3n/2) finer ones, not 2n. An embedded pair
(dopri5) doubles the sub-steps its error control took (embedded.py). Checks come every
FIRST_EVERY steps at first, then as often as the local error moves (shadow.py: up to every
MAX_EVERY; at rest, every MAX_EVERY). Switching scenes
(events.py): a step with a located switch or an engaged compliant limit is checked, each
piece doubled, the halves going on from their own state between switches (attempt).

Global error (`accumulated_error`, shadow.py): the shadow takes the same steps as the run
from the estimated true state, less each step's local error; the run's largest distance
from it, within a factor of 10 of the true error on every preset, integrator and random
scene (test/physics/test_error_estimate.py). Past LOST (1 rad) the run says once that it no
longer follows the true motion.

Tolerance (controller.py): the scaled error max(|e_q|, |e_qd| / (1 + |qd|)) of a step is
held under tolerance x h (per simulated second, so the bound on the drift does not depend
on h; angles unscaled: unwrapped, their size says nothing), never under ROUNDING. A PI
controller sets the sub-step count both ways; a step that misses is taken again; the
stability plan's count is the floor and `max_substeps` the ceiling, said once when it
cannot meet the tolerance, as is a tolerance that splitting does not reach. Compliant
contact, free flight and the pieces up to a located switch are controlled apart. 0 turns
the controller off (estimate only). Default (DEFAULT_TOLERANCE = 5e-5 per s): a 100 rad/s
spin drifts 2.9e-7 of its energy over 5 s at h = 10 ms, 6.9e-7 at 1 ms.
"""
from __future__ import annotations

from ..stepping import stability
from .controller import SAFETY, Control, retake, said_count, said_lost, said_unreachable
from .shadow import FIRST_EVERY, ROUNDING, Shadow, Twin, next_every
from .embedded import Embedded
from .unestimated import Off, Unchecked

NO_GAIN, GIVE_UP = 0.9, 16   # 16x the sub-steps leaving 90 % of the error: none to buy
THREE_LEVELS = 12            # sub-steps from which a split step is checked against coarser ones
DEFAULT_MAX_SUBSTEPS = 1000   # the tolerance's ceiling per step (scene key max_substeps)
MAX_SUBSTEPS = stability.MAX_SUBSTEPS   # what a scene may set it to
# Per simulated second, scaled error (see above); 0 = off (estimate only).
DEFAULT_TOLERANCE = 5e-5


class Accuracy:
    """The error books of a fixed-step method. The simulator takes `plain(f, y, h)` (the
    planned step, nothing else) while its step index is below `due`, else `check(f, y, h)`;
    the estimate is carried between checks, so the sums are counted when asked for."""

    def __init__(self, step, order: int, tolerance: float, width: int, substeps: int = 1,
                 emit=None, clock=None, stepper=None, cap: int = DEFAULT_MAX_SUBSTEPS,
                 states: int = 4, twin=None, stiff_below: float = 0.0):
        self.step, self.order, self.tolerance, self.width = step, order, tolerance, width
        self.stiff_below = stiff_below   # fewer sub-steps do not decay as the flow does
        self.states = states          # q, qd and the effects' extra states (currents)
        self.twin = twin              # a second switching stepper for the shadow, or None
        self.factor = 2.0 ** order / (2.0 ** order - 1.0)
        self.base = substeps          # the stability plan's count: never fewer
        self.ceiling = max(substeps, cap)  # the tolerance's ceiling (max_substeps)
        self.emit = emit              # emit(kind, message)
        self.clock = clock            # the simulator's step index (the step being taken)
        self.stepper = stepper        # events.Switching: it steps, pieces are estimated
        if stepper is not None:       # ... and a step with a switch or a contact always
            stepper.checked = self.check
        self.reset()

    def reset(self) -> None:
        self.error_estimate = 0.0     # the latest check's local error estimate
        self.since = self.due = 0     # step index of the latest check; of the next
        self.booked_taken = 0         # sub-steps run in split steps before `since`
        self.shadow = Shadow(self.states)
        self.every = FIRST_EVERY      # steps between checks (schedule): often until it is smooth
        self.tried = {}               # a switching step's attempts: part -> (count, scaled)
        self.cap = self.ceiling       # lowered where the tolerance cannot be reached
        self.free = Control(self.base, self.cap)
        self.contact = Control(0, self.cap)      # engaged pieces (switching stepper)
        self.most = self.base         # the largest count said so far
        self.capped = self.said_lost = False   # said once: not met at the cap; the motion lost
        self.substeps = -1
        self.use(self.base)
        if self.stepper is not None:
            self.stepper.contact_substeps = 0

    def use(self, n: int) -> None:
        """Take n equal sub-steps from now on."""
        self.free.n = n
        if self.stepper is not None:   # (a retaken switching step may have raised it)
            self.stepper.substeps = n
        if n != self.substeps:
            self.substeps = n
            if self.stepper is not None:
                self.advance = self.stepper.advance
            else:
                self.advance = stability.substepping(self.step, n)
            self.shadow_advance = Twin(self.stepper, self.twin) if self.twin else self.advance

    def plain(self, f, y, h):
        """The planned step, and the shadow's beside it."""
        before = self.stepper.total if self.stepper is not None else 0
        y1 = self.advance(f, y, h)
        if self.shadow.last is not y1:   # (a switching step may have been checked instead)
            self.shadow.follow(self.shadow_advance, f, y, y1, h, self.twin, before != (
                self.stepper.total if self.stepper is not None else 0))
            if self.shadow.lost:            # said when it is, not at the next check
                said_lost(self, self.clock() if self.clock else 0, h)
        return y1

    def carry(self, previous, steps: int) -> None:
        """Go on from the books `previous` after `steps` steps (their shadow), checked now."""
        self.shadow.carry(previous.shadow)
        self.booked_taken = previous.taken(steps) or 0
        self.since = self.due = steps

    def accumulated(self) -> float:
        return self.shadow.largest        # the global error estimate (shadow.py)

    def taken(self, steps: int) -> int:
        """Sub-steps run in split steps over `steps` steps since reset (0: plain steps),
        those the switching stepper adds (contacts, re-splits after a switch) included."""
        return self.booked_taken + (self.substeps * (steps - self.since)
                                    if self.substeps > 1 else 0) + (
            self.stepper.extra_substeps if self.stepper is not None else 0)

    def doubled(self, f, y, h, full, n=1, apart=None) -> tuple[float, float, list]:
        """(local error, scaled error, signed error of every state) of y -> full (n sub-steps
        of h) against 2n half sub-steps, x 2^p / (2^p - 1) (Richardson). `apart` (attempt):
        the halves start that far from y, and what this piece grows is added to it."""
        if apart is not None:
            y = [a - d for a, d in zip(y, apart)] + list(y[self.states:])
        hs = 0.5 * h / n
        for _ in range(2 * n):
            y = self.step(f, y, hs)
        grown = [a - b - d for a, b, d in zip(full[:self.states], y, apart or [0.0] * len(y))]
        if apart is not None:
            apart[:] = [d + g for d, g in zip(apart, grown)]
        return sized([g * self.factor for g in grown], full, self.width)

    def measure(self, f, y, h, n):
        """(the step as n sub-steps, its error, its scaled error, its signed error): against
        other counts of its sub-steps where it is split (compared), else against 2 halves."""
        full = self.advance(f, y, h) if n == self.substeps else stability.substepping(
            self.step, n)(f, y, h)
        return full, *(compared(self, f, y, h, full, n) or self.doubled(f, y, h, full, n))

    def target(self, h: float) -> float:
        """The scaled error a step may make: tolerance x h, never under ROUNDING."""
        return max(self.tolerance * h, ROUNDING)

    def ratio(self, scaled: float, h: float) -> float:
        return scaled / (SAFETY * self.target(h))

    def check(self, f, y, h):
        """The step, measured; a miss of the tolerance is taken again at the count the
        controller asks for (until it passes or the cap is reached)."""
        index, n = self.clock(), self.substeps
        if self.stepper is not None:
            return self.switching(f, y, h, index, n)
        y1, error, scaled, signed = self.measure(f, y, h, n)
        if scaled - scaled != 0.0:     # a step that leaves the finite numbers: refused as it
            return y1                  # is (simulator.py), nothing to control or book
        first, wanted = scaled, n
        if self.tolerance:
            wanted = self.free.ask(self.ratio(scaled, h), self.order)
            start = (n, scaled)
            while scaled > self.target(h) and n < self.cap:      # a miss: retaken
                n = retake(n, self.ratio(scaled, h), self.order, self.cap)
                y1, error, scaled, signed = self.measure(f, y, h, n)
                self.free.n = n
                if n >= GIVE_UP * start[0] and scaled > NO_GAIN * start[1]:   # no gain
                    said_unreachable(self, scaled, n, h)
                    break
                wanted = self.free.ask(self.ratio(scaled, h), self.order)
        predicted, self.shadow.local = self.shadow.local, signed
        self.shadow.follow(stability.substepping(self.step, n), f, y, y1, h,
                           measure=at_shadow(self, n))
        self.book(index, error, scaled, n, h, first, wanted, predicted)
        return y1

    def switching(self, f, y, h, index, n):
        """A step of a switching scene: every sub-step (each smooth piece between located
        switches) doubled, errors summed, free flight and compliant contact apart. A step
        that misses the tolerance is taken again with more sub-steps where it missed (its
        switches, counts and messages as the last attempt has them), so the error made at
        a switch is controlled like any other."""
        stepper = self.stepper
        stepper.located_substeps = 1      # raised below where a located piece misses
        kept, emit, heard = keep(stepper), stepper.emit, []
        stepper.emit = lambda kind, message: heard.append((kind, message))
        try:
            y1, sums, signed = attempt(self, f, y, h)
            while self.tolerance and more(self, sums, h):
                restore(stepper, kept)
                heard.clear()
                y1, sums, signed = attempt(self, f, y, h)
        finally:
            stepper.emit = emit
        for kind, message in heard:
            emit(kind, message)
        predicted, self.shadow.local = self.shadow.local, signed
        switched = stepper.total != kept[2]
        self.shadow.follow(self.shadow_advance, f, y, y1, h, self.twin, switched)
        if sums[True][2] or switched:
            # a switch's or a contact's error is its step's own: the steps after carry the
            # latest smooth estimate, and are checked again soon
            self.shadow.local = predicted or [0.0] * self.states
            predicted = None
        error, scaled = (sum(part[k] for part in sums.values()) for k in (0, 1))
        wanted = n = stepper.substeps
        if self.tolerance:
            if sums[False][2]:
                wanted = self.free.ask(self.ratio(sums[False][1], h), self.order)
            if sums[True][2]:                # compliant contact: its own count
                self.contact.floor = stepper.contact_floor(h)
                self.contact.n = stepper.substeps_for(h, True)
                stepper.contact_substeps = self.contact.ask(self.ratio(sums[True][1], h),
                                                            self.order)
                said_count(self, stepper.contact_substeps, sums[True][1], h, sums[True][1],
                           " while a compliant limit is engaged")
        self.book(index, error, scaled, n, h, scaled, wanted, predicted, predicted is None)
        return y1

    def book(self, index, error, scaled, n, h, first, wanted, predicted=None, soon=False):
        """Close the books up to step `index` (which took n sub-steps and made `error`) and
        carry this estimate from it on (predicted at the new count)."""
        measured = self.shadow.local
        carried = index - self.since            # steps that carried the latest estimate
        self.booked_taken += (self.substeps * carried if self.substeps > 1 else 0) + (
            n if n > 1 else 0)
        self.since = index + 1
        self.error_estimate = error
        if wanted != n:                # the shadow's correction, predicted at the new count
            scale = (n / wanted) ** self.order
            self.shadow.local = [e * scale for e in self.shadow.local]
        self.use(wanted)
        # after a switch (or a first estimate) the schedule starts afresh; a new count's
        # error is measured, not predicted (the n^-p law fails in a stiff transient: 16x)
        self.every = FIRST_EVERY if soon else next_every(self.every, predicted, measured,
                                                         carried + 1)
        self.due = index + (1 if soon or wanted != n else self.every)
        said_lost(self, index, h)
        if self.tolerance:
            said_count(self, wanted, first, h, scaled)


def compared(books, f, y, h, full, n):
    """(local error, scaled error, signed error of every state) of y -> full (n > 1 sub-steps
    of h), by Richardson against other counts of the same sub-steps, whose errors go as
    e(N) = C N^-p + D N^-(p+1) + ...: from THREE_LEVELS sub-steps on, against ceil(n/2) and
    ceil(n/3) coarser ones, C and D solved for (5n/6 sub-steps), where those are as stable as
    the plan asks (base) and not too stiff to decay as the flow does (stiff_below); else
    against ceil(3n/2) finer ones. None at n = 1 (the halves). Against ceil(n/2) alone
    (C alone) the estimate carried D 2.07 times where the halves carry it 1.03 times: 5-30 %
    off on a fast spin's steps, and its bias, unlike the true errors, did not cancel over a
    turn (a 100 rad/s spin at 10 ms, 5 s: 11.5x the true error; at 1 ms, with 100 and
    -60 rad/s: 0.014x)."""
    if n < 2:
        return None
    p, m1, m2 = books.order, (n + 1) // 2, -(-n // 3)
    if n >= THREE_LEVELS and m2 >= books.base and not m2 < books.stiff_below:
        r1, r2 = n / m1, n / m2
        det = (r1 ** p - 1.0) * (r2 ** (p + 1) - 1.0) - (r1 ** (p + 1) - 1.0) * (r2 ** p - 1.0)
        w1, w2 = r2 ** p * (r2 - 1.0) / det, -(r1 ** p) * (r1 - 1.0) / det
        one, two = (stability.substepping(books.step, m)(f, y, h) for m in (m1, m2))
        signed = [w1 * (a - b) + w2 * (c - b) for a, c, b in zip(one, two, full[:books.states])]
    else:
        m = (3 * n + 1) // 2
        fine = stability.substepping(books.step, m)(f, y, h)
        ratio = 1.0 - (n / m) ** p
        signed = [(b - a) / ratio for a, b in zip(fine, full[:books.states])]
    return sized(signed, full, books.width)


def sized(signed, full, width: int) -> tuple[float, float, list]:
    """(local error, scaled error, signed error of every state) of the signed errors."""
    errors = [abs(e) for e in signed[:width]]   # angles unwrapped: not scaled
    scaled = max(max(errors[:2]), *(e / (1.0 + abs(a)) for e, a in zip(errors[2:], full[2:])))
    return max(errors), scaled, signed


def at_shadow(books, n):
    """How the shadow's local error is measured after a step of n sub-steps: where the step
    is too stiff to decay as the flow does (past stability.SUBSTEP_FRACTION of its limit:
    RK4 at d h Lambda = 2.75 keeps 95 % of a fast mode the flow keeps 6 % of), the motion's
    local error is mostly the part of its error its step fails to damp, which the shadow's
    step propagates again: there it is measured where the shadow is (a damped arm at
    h = 0.02, 9.7x pessimistic, is 1.0x so). Else (None) the motion's stands for it."""
    if not n < books.stiff_below:
        return None
    return lambda f, z, z1, h: books.doubled(f, z, h, z1, n)[2]


def attempt(books, f, y, h):
    """(the step, {part: [error, scaled, pieces]}, signed error) with every piece doubled;
    the parts: free flight (False), compliant contact (True), pieces up to a located switch
    (None: their length is the switch's, so only their own count can shorten them)."""
    sums = {False: [0.0, 0.0, 0], True: [0.0, 0.0, 0], None: [0.0, 0.0, 0]}
    stepper, signed, apart = books.stepper, [0.0] * books.states, [0.0] * books.states

    def piece(rhs, y0, dt, full, located=0):
        # the halves go on between switches: an early error carried as the motion carries it
        error, scaled, vector = books.doubled(rhs, y0, dt, full, located or 1,
                                              None if located else apart)
        if located:                       # after a switch the halves start afresh
            apart[:] = [0.0] * books.states
        part = sums[None if located else bool(stepper.mode[2] or stepper.mode[3])]
        part[0] += error
        part[1] += scaled
        part[2] += 1
        signed[:] = [a + b for a, b in zip(signed, vector)]

    return stepper.advance(f, y, h, piece), sums, signed

def more(books, sums, h) -> bool:
    """Raise the counts of the parts (free flight, contact, located pieces) that missed the
    tolerance; False when none did, or none can be raised (the cap, or no gain: said once)."""
    stepper, raised = books.stepper, False
    for part, (_, scaled, pieces) in sums.items():
        if not pieces or scaled <= books.target(h):
            continue
        now = stepper.located_substeps if part is None else stepper.substeps_for(h, True) \
            if part else stepper.substeps
        first = books.tried.setdefault(part, (now, scaled))
        if now >= GIVE_UP * first[0] and scaled > NO_GAIN * first[1]:
            said_unreachable(books, scaled, now, h)      # more sub-steps bought nothing
            continue
        wanted = retake(now, books.ratio(scaled, h), books.order, books.cap)
        if wanted > now:
            if part is None:
                stepper.located_substeps = wanted
            elif part:
                stepper.contact_substeps = wanted
            else:
                stepper.substeps = books.free.n = wanted
            raised = True
    if not raised:
        books.tried = {}
    return raised


def keep(stepper) -> tuple:
    """What a switching step changes in its stepper, to take the step again."""
    return stepper.mode, stepper.last, stepper.total, dict(stepper.counts), stepper.extra_substeps


def restore(stepper, kept) -> None:
    stepper.mode, stepper.last, stepper.total, counts, stepper.extra_substeps = kept
    stepper.counts.clear()
    stepper.counts.update(counts)


def plan(tableau, step, substeps: int, tolerance: float, width: int, emit=None,
         clock=None, stepper=None, previous=None, cap: int = DEFAULT_MAX_SUBSTEPS,
         states: int = 4, twin=None, estimate: str = "global", stiffness: float = 0.0,
         stiff: str = "damping"):
    """The error books, with the step they take (`step` as the stability plan's `substeps`
    equal sub-steps): the embedded pair's own estimate, or checked equal sub-steps (over the
    stability plan's) of a fixed-step method, switched at events by `stepper` if any; with
    `estimate` off, the planned steps alone (unestimated.Off). `previous`: the books so far
    (a payload grasped rebuilds the dynamics mid-run); `stiffness`: the stability plan's
    ratio over its limit (at_shadow); `stiff`: the effects that make it stiff (a refusal
    names them)."""
    if estimate == "off":
        return Off(stepper.advance if stepper is not None else
                   stability.substepping(step, substeps), substeps, stepper)
    if getattr(tableau, "adaptive", False) and stepper is not None:
        # dopri5 between located switches: its pieces' own estimates are not summed (NaN);
        # without the switches its error control would chase the kink forever.
        return Unchecked(stepper.advance, substeps, stepper)
    if getattr(tableau, "adaptive", False):
        books = Embedded(step, tableau, states, clock)   # (it plans no sub-steps)
    elif substeps > stability.MAX_SUBSTEPS:   # the stability plan refuses: keep its refusal
        return Unchecked(stability.substepping(step, substeps, stiff), substeps)
    else:
        books = Accuracy(step, tableau.order, tolerance, width, substeps, emit, clock, stepper,
                         cap, states, twin, stiffness / stability.SUBSTEP_FRACTION)
    if previous is not None:        # go on from here: the sums so far, a check at once
        books.carry(previous, clock())
    return books
