"""The global error, propagated along the motion, and the schedule of the checks that
measure the local error it is built from (accuracy.py).
"""
from __future__ import annotations

# Steps between checks (a check: 2 steps' evaluations, or half a split step's): FIRST_EVERY first,
FIRST_EVERY, MIN_EVERY, MAX_EVERY = 2, 1, 32   # then as often as the local error moves:
ROUGH, SMOOTH = 0.5, 0.125     # twice as often past ROUGH x its size (down to every step: a
                               # local error that turns within 4 steps, checked every 2, can
                               # be seen at its zeros only), half as often under SMOOTH x it
LOST = 1.0                # rad (velocities scaled): a global error beyond this has lost the motion
ROUNDING = 1e-13          # doubles' rounding: the least scaled error per step a tolerance asks
                          # for (accuracy.py); a local error under it moves as it likes


def next_every(every: int, predicted, measured, spacing: int | None = None) -> int:
    """Steps to the next check: the shadow carries each check's local error to the steps
    after it, which is right while that error moves slowly; where it moves as fast as its
    size (an elbow whipping, a joint about to stick) checks come more often. Rounding
    moves as fast as its size: a local error at rounding is measured against ROUNDING (at
    rest checks grow as rare as MAX_EVERY). A check `spacing` steps after the last, sooner
    than the schedule's (a new command, a new count), can say the error moves fast, never
    that it moves slowly over `every` steps (a spin's error, turning every 63 steps, held
    for 32 at a time so: 14.5x)."""
    if predicted is not None:
        change = max(abs(a - b) for a, b in zip(measured[:4], predicted[:4]))
        size = max(ROUNDING, *(abs(a) for a in measured[:4]), *(abs(b) for b in predicted[:4]))
        if change > ROUGH * size:
            return max(MIN_EVERY, every // 2)
        if change < SMOOTH * size and (spacing is None or spacing >= every):
            return min(MAX_EVERY, 2 * every)
    return every


class Shadow:
    """The global error, propagated along the motion. The shadow takes the same steps as
    the motion, from the estimated true state, less each step's estimated local error (the
    latest check's, signed, carried between checks): it follows the true motion, and the
    motion's distance from it is the global error as it is, contracted where the motion
    contracts errors (damping, an attracting hold, a joint that sticks), grown where it
    grows them, and carried through every switch at the shadow's own time (an impact's
    timing becomes a velocity error). `largest` is the largest distance since reset."""

    def __init__(self, states: int):
        self.states = states
        self.local = None            # signed local error of every state per step
        self.offset = None           # motion - shadow at `last` (None: none yet)
        self.last = self.shadow = None
        self.largest = 0.0
        self.lost = False            # the distance passed LOST: no longer followed
        self.sampled = None          # a discrete servo: the shadow steps under its own samples

    def carry(self, previous) -> None:
        """Go on from the shadow `previous` (None: books without one; start afresh)."""
        if previous is None:
            return
        self.largest, self.local = previous.largest, None
        if previous.offset is not None:
            self.offset = list(previous.offset[:4]) + [0.0] * (self.states - 4)

    def follow(self, advance, f, y, y1, h, twin=None, switched=False, measure=None) -> None:
        """After the motion's step y -> y1 (`switched`: a switch in it): the shadow's step
        (by `advance`); `measure(f, z, z1, h)`: its local error, measured where it is."""
        if sum(y1[:4]) - sum(y1[:4]) != 0.0:   # the motion's step is refused: no shadow
            return
        z = self.start(y)
        if z is not None:
            before = twin.total if twin is not None else 0
            z1 = advance(f, z, h) if self.sampled is None else self.sampled.beside(
                advance, f, z, h)
            if measure is not None:
                self.local = measure(f, z, z1, h)
            switched = switched or (twin is not None and twin.total != before)
            self.land(z1, y1, 1, twin, switched)

    def answered(self) -> None:
        """A new torque from outside: a controller's answer to the state it read (a loop
        the shadow does not see, whose gains nobody tells). Its answer holds the arm at the
        motion's velocity as well as the true arm at the true one, so the shadow takes the
        motion's velocity here, its position offset carried: a shadow left at a velocity
        no controller answers drifts without end under the held command (a neutral arm,
        gravity fed forward: a held arm's estimate grew 10x every 10 s, its true error at
        rounding; measured against the loop closed around h/16, 0.3-0.4x with the shipped
        JTC gains)."""
        if self.offset is not None and not self.lost:
            self.offset, self.last = self.offset[:2] + [0.0, 0.0] + self.offset[4:], None

    def start(self, y):
        """The shadow's state beside the motion's y, to step from (None: not followed)."""
        if self.local is None or self.lost:   # no estimate yet: the shadow is the motion
            return None
        if y is not self.last:        # reset, or a state set from outside: same offset
            n, offset = self.states, self.offset or [0.0] * self.states
            self.shadow = (*(a - e for a, e in zip(y[:n], offset)), *y[n:])
        return self.shadow

    def land(self, z1, y1, steps: int = 1, twin=None, switched=False) -> None:
        """The shadow stepped `steps` steps to z1, less their local errors (over a few steps
        the motion carries a correction almost unchanged), beside the motion's y1. In a step
        where either switched, velocities are not compared: an impact a step apart in the
        two (a hair's difference in the time of arrival) is a jump, not an error."""
        n = self.states
        z1 = (*(a - steps * e for a, e in zip(z1[:n], self.local)), *z1[n:])
        if twin is not None:
            twin.last = z1            # its mode goes on from the corrected state
        offset = [a - b for a, b in zip(y1[:n], z1[:n])]
        seen = offset[:2] if switched else offset[:4]
        distance = max(abs(v) for v in seen)
        scaled = max(abs(offset[0]), abs(offset[1]), *(() if switched else (
            abs(offset[2]) / (1.0 + abs(y1[2])), abs(offset[3]) / (1.0 + abs(y1[3])))))
        if not scaled <= LOST:        # NaN too: the motion is lost, its error unknowable
            self.lost, distance = True, max(self.largest, LOST)
        self.largest = max(self.largest, distance)
        self.shadow, self.offset, self.last = z1, offset, y1


class Twin:
    """The shadow's step on a switching stepper of its own (its modes switch at its own
    times), at the counts the motion's stepper uses."""

    def __init__(self, stepper, twin):
        self.stepper, self.twin = stepper, twin

    def __call__(self, f, z, h):
        self.twin.substeps = self.stepper.substeps
        self.twin.contact_substeps = self.stepper.contact_substeps
        self.twin.located_substeps = self.stepper.located_substeps
        return self.twin.advance(f, z, h)
