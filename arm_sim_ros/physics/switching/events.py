"""Non-smooth effects (friction, joint limits, clamps) switched at events located inside
the step.

Each joint has a mode (dynamics.mode_functions): a code, "+"/"-" sliding with friction,
"stuck", "lower"/"upper" resting on a hard limit (those three fix the joint: a constraint
whose holding torque lamᵢ comes out of the solve), "free"; and a zone, 1/-1 beyond a
compliant limit, else 0; with clamps of a state-dependent request (clamps.py) a fifth
entry, their modes. Within a mode the right-hand side is smooth, so RK4 keeps its
order; the effects' switching functions g (Effect.guards) say when a mode ends (g < 0).

A step is taken as before (the stability plan's equal sub-steps; more while a compliant
limit is engaged, whose stiffness counts only then). After each sub-step the switching
functions are evaluated at its end and, where an angle turns or a velocity has an
extremum inside it, between its ends (dense.py: a mode that ends and comes back within
one sub-step); when one went negative the event is located by re-stepping from the
sub-step's start with a shorter step (Illinois regula falsi, bracket < 1e-12 s), the
switch is applied there (an impulse at an impact, q̇ᵢ = 0 exactly at a stop), and the step
goes on from there in the new mode. It still ends exactly at the step boundary: the
remaining time is re-split into equal sub-steps. Every switch is located; past
MAX_EVENTS_PER_STEP in one step (Zeno chatter at a stop) impacts are plastic, so the joint
comes to rest on its stop with the energy booked and settle() decides whether it stays.
`locate = False` switches at the end of the sub-step instead (first order; for the
convergence test and benchmark).
"""
from __future__ import annotations

from collections import Counter
from math import ceil

from .. import model
from ..dynamics import mode_functions
from ..effects import Effect
from ..stepping import stability
from .clamps import KINDS as CLAMPS, Clamps
from .dense import ended

TIME_TOLERANCE = 1e-12    # s: an event's time is known to this (the bracket's width)
MAX_EVENTS_PER_STEP = 64  # beyond this (chattering) impacts are plastic: rest on the stop
MAX_SWITCHES = 4096       # beyond this in one step the step is refused (never a hang)
REST_SPEED = 1e-4         # rad/s: a bounce slower than this (e < 1) ends at rest on the limit
CONTACT_RESOLUTION = 0.25  # h_sub |λ| while a compliant limit is engaged: ~12 sub-steps a swing
STEEP = 4.0               # Stribeck velocities: within this a sliding joint's step is estimated
EMIT_FIRST = 5            # events reported one by one; then a summary at 10, 100, 1000 ...


class Engaged(Effect):
    """A compliant limit's stiffness and damping as the planner sees them while engaged."""

    name = "joint_limits beyond"

    def __init__(self, limits, arm):
        self.decay, self.omega = limits.engaged_stiffness(arm), limits.engaged_frequency(arm)

    def stiffness(self, arm) -> float:
        return self.decay

    def frequency(self, arm) -> float:
        return self.omega


def switching(dynamics, tableau, step, substeps: int, emit, clock, counts=None):
    """The switching stepper for a scene with non-smooth effects; None without any: then
    nothing here runs. `emit(kind, message)` reports, `clock()` is the step's start time,
    `counts` carries the counts on (a payload grasped rebuilds the dynamics)."""
    if not any(e.switching for e in dynamics.active):
        return None
    return Switching(dynamics, tableau, step, substeps, emit, clock, counts)


class Switching:
    plastic = False          # impacts leave at rest (a step's switches passed the quota)

    def __init__(self, dynamics, tableau, step, substeps, emit, clock, counts=None):
        self.dynamics, self.arm, self.step, self.emit = dynamics, dynamics.arm, step, emit
        self.clock, self.counts = clock, Counter() if counts is None else counts
        self.total = sum(self.counts.values())   # switches since reset (counts carried on)
        effects = {e.name: e for e in dynamics.active}
        self.friction, self.limits = effects.get("friction"), effects.get("joint_limits")
        self.hard = self.limits is not None and self.limits.hard
        self.width = 4 + len(dynamics.extra)
        self.impact_at = (self.width + dynamics.channels.index("impact_loss")
                          if "impact_loss" in dynamics.channels else None)
        self.substeps, self.engaged_rate = substeps, 0.0
        self.contact_substeps = 0         # the tolerance's count while engaged (accuracy.py)
        self.located_substeps = 1         # ...and of a re-step up to a located switch
        if self.limits is not None and not self.hard:
            # h |λ| of the engaged arm per unit step (the step size is the plan's business)
            ratio, _, _ = stability.bound(tableau, list(dynamics.active)
                                          + [Engaged(self.limits, self.arm)], self.arm, 1.0)
            self.engaged_rate = ratio
        self.clamps = Clamps.of(dynamics)  # effort, voltage clamps of a state-dependent request
        self.locate = True                # False: switch at sub-step ends (first order)
        self.checked = None               # advance, estimated (accuracy.py), or None
        self.extra_substeps = 0           # sub-steps taken beyond the planned count since reset
        # `last`: the state the mode belongs to (the shadow's stepper sets it, accuracy.py)
        self._functions, self.mode, self.last = {}, None, None

    def reset(self) -> Counter:
        """Forget the mode (found again from the next state) and the counts (returned)."""
        self.counts.clear()
        self.mode, self.last, self.extra_substeps, self.total = None, None, 0, 0
        return self.counts

    # --- modes ---------------------------------------------------------------------------

    def functions(self, mode):
        """(rhs, probe, guard, guard kinds, the clamps' requests) of a mode, compiled once."""
        if mode not in self._functions:
            guards = [g for e in self.dynamics.active if e.switching for g in e.guards(mode)]
            rhs, probe, guard, requests = mode_functions(
                self.dynamics, mode, [g[0] for g in guards], self.clamps and self.clamps.requests)
            self._functions[mode] = rhs, probe, guard, [g[1:] for g in guards], requests
        return self._functions[mode]

    def clamped(self, y, mode) -> tuple:
        """`mode` with the clamps' modes the state y calls for (itself without clamps)."""
        return mode if self.clamps is None else self.clamps.found(
            y[:self.width], mode, lambda m: self.functions(m)[4])

    def settle(self, y, mode) -> tuple:
        """The mode with every fixed joint's holding torque admissible: within ±Fsᵢ when
        stuck, pushing away from a hard limit it rests on. The worst violator is released
        first (a stuck joint slips toward the net torque; a resting one comes free)."""
        for _ in range(6):
            lam = self.functions(mode)[1](*y[:self.width])[:2]
            worst, which = 0.0, None
            for i in (0, 1):
                code = mode[i]
                excess = (abs(lam[i]) - self.friction.static[i] if code == "stuck" else
                          lam[i] if code == "upper" else -lam[i] if code == "lower" else 0.0)
                if excess > worst:
                    worst, which = excess, i
            if which is None:
                return mode
            mode = release(self, mode, which, y, lam[which])
        return mode

    def contact_floor(self, h: float) -> int:   # resolves an engaged limit: ~12 a swing
        return ceil(h * self.engaged_rate / CONTACT_RESOLUTION)

    def substeps_for(self, h: float, engaged: bool) -> int:
        """The free count; engaged, the most of it, the contact floor and the tolerance's."""
        return max(self.substeps, self.contact_floor(h), self.contact_substeps) if engaged \
            else self.substeps

    # --- stepping ------------------------------------------------------------------------

    def advance(self, f, y, h, piece=None):
        """step(f, y, h) with every switch inside the step located and applied (f unused:
        each mode has its own right-hand side). `piece(rhs, y0, dt, y1)` is told every
        smooth sub-step taken, up to a located switch (accuracy.py estimates them)."""
        if y is not self.last:                  # reset, or a state set from outside
            self.mode = self.settle(y, self.clamped(y, initial_mode(self, y)))
        elif self.clamps is not None and self.clamps.stale():   # a new command
            self.mode = self.settle(y, self.clamped(y, self.mode))
        rhs, _, guard, kinds, _ = self.functions(self.mode)
        engaged = self.mode[2] or self.mode[3] or steep(self, y)   # contact, or Stribeck's
        if self.substeps == 1 and not engaged:        # the common case
            y1 = self.step(rhs, y, h)
            if not kinds or ended(self.step, rhs, guard, self.width, y, y1, h) is None:
                if piece is not None:
                    piece(rhs, y, h, y1)
                self.last = y1
                return y1
        if piece is None and self.checked is not None and (self.substeps == 1 or engaged):
            return self.checked(f, y, h)     # a switch inside or a contact: estimate it
        start, remaining, events, taken = y, h, 0, 0
        while remaining > 1e-15 * h:
            mode = self.mode
            rhs, _, guard, kinds, _ = self.functions(mode)
            cap = h / bounded(self.substeps_for(h, bool(mode[2] or mode[3])))
            count = max(1, ceil(remaining / cap - 1e-9))
            dt = remaining / count
            for k in range(count):
                y1 = self.step(rhs, y, dt)
                cut = ended(self.step, rhs, guard, self.width, y, y1, dt) if kinds else None
                if cut is None:
                    if piece is not None:
                        piece(rhs, y, dt, y1)
                    y = y1
                    continue
                if piece is None and self.checked is not None and not events:
                    return self.checked(f, start, h)   # a switch inside: estimate the step
                elapsed = h - remaining + k * dt          # from the step's start
                if self.locate:
                    self.plastic = chattering(events)   # Zeno at a stop: rest on it
                    t, y = locate(self, rhs, guard, kinds, y, cut, elapsed, piece)
                else:
                    if piece is not None:
                        piece(rhs, y, dt, y1)
                    t, y = dt, self.apply(y1, fired(guard, kinds, y1[:self.width]), False,
                                          elapsed + dt)
                events += 1
                remaining -= k * dt + t
                taken += k + (t > 0.0)            # the sub-steps before, the one cut short
                break
            else:
                remaining = 0.0
                taken += count
        if taken > self.substeps:                 # engaged, or re-split after a switch
            self.extra_substeps += taken - (self.substeps if self.substeps > 1 else 0)
        self.last = y = tuple(y)
        return y

    # --- switches ------------------------------------------------------------------------

    def apply(self, y, fired, located=True, at=0.0):
        """The state and mode after the switches `fired` ((kind, joint), most negative g
        first) at state y."""
        y, mode = list(y), list(self.mode)
        for kind, i in fired[:1] if fired and fired[0][0] == "impact" else fired:
            if kind == "stop":
                y[2 + i], mode[i] = 0.0, "stuck"
            elif kind == "release":
                mode[i] = "stuck" if self.friction is not None else "free"
            elif kind == "enter":
                mode[2 + i] = 1 if y[i] > self.limits.upper[i] else -1
            elif kind == "leave":
                mode[2 + i] = 0
            elif kind == "impact":
                impulse(self, y, mode, i, located)
        too = stopping_too(self, y, mode) if any(kind == "stop" for kind, _ in fired) else []
        self.mode = self.settle(y, self.clamped(y, tuple(mode)))   # clamps: found from y
        for kind, i in fired[:1] + too:
            if kind == "stop":
                kind = "stick" if self.mode[i] == "stuck" else "reverse"
            elif kind == "impact":
                kind = "rest" if self.mode[i] in ("lower", "upper") else "impact"
            elif kind in CLAMPS:
                kind = self.clamps.kind(kind, i, self.mode)
            self.count(kind, i, at)
        return y

    def count(self, kind: str, joint: int, at) -> None:
        self.counts[kind] += 1
        self.total = total = self.total + 1
        when = f"{self.clock() + at:.9f} s"
        if total <= EMIT_FIRST:
            self.emit("switch", f"{kind} of joint {joint + 1} at t = {when}")
        elif total >= 10 and str(total).rstrip("0") == "1":     # 10, 100, 1000 ...
            counts = ", ".join(f"{k} {n}" for k, n in sorted(self.counts.items()))
            self.emit("switch", f"{total} switches so far ({counts}); latest at t = {when}")


def locate(stepper, rhs, guard, kinds, y0, dt, elapsed, piece=None):
    """(t, state after the switch): the earliest root of min g in [0, dt] by Illinois
    regula falsi on re-steps of length t from y0, to TIME_TOLERANCE; `piece` is told
    the smooth re-step up to the switch."""
    m = stepper.located_substeps     # the tolerance's count for such a piece

    def g(t):
        y = y0
        for _ in range(m if t > 0.0 else 0):
            y = stepper.step(rhs, y, t / m)
        return min(guard(*y[:stepper.width])), y

    (ga, ya), (gb, yb) = g(0.0), g(dt)
    a, b, side = 0.0, dt, 0
    if ga < 0.0:                                  # already past (rounding): switch now
        b, yb = 0.0, y0
    for _ in range(200):
        if b - a <= TIME_TOLERANCE:
            break
        t = (a * gb - b * ga) / (gb - ga) if gb != ga else 0.5 * (a + b)
        if not a < t < b or side == 3:         # safeguard: bisect
            t, side = 0.5 * (a + b), 0
        gt, yt = g(t)
        if gt < 0.0:
            b, gb, yb = t, gt, yt
            ga, side = (0.5 * ga, side + 1) if side > 0 else (ga, 1)
        else:
            a, ga, ya = t, gt, yt
            gb, side = (0.5 * gb, side + 1) if side > 0 else (gb, 1)
    switches = fired(guard, kinds, yb[:stepper.width])
    impact = switches and switches[0][0] == "impact"   # arrive, not pass: the state before
    t, y = (a, ya) if impact else (b, yb)
    if piece is not None and t > 0.0:
        piece(rhs, y0, t, y, m)
    return t, stepper.apply(y, switches[:1] if impact else switches, at=elapsed + b)


def steep(stepper, y) -> bool:
    """A joint sliding through Stribeck's dip (|q̇| within STEEP x its velocity): the
    friction law changes faster than anywhere else, so the step is estimated (accuracy.py),
    like one with a contact, not carried from the last check."""
    friction = stepper.friction
    if friction is None or not friction.stribeck_velocity:
        return False
    near = STEEP * friction.stribeck_velocity
    return any(stepper.mode[i] in ("+", "-") and abs(y[2 + i]) < near for i in (0, 1))


def chattering(events: int) -> bool:
    """A step's switches past the quota: impacts end at rest (Zeno chatter at a stop),
    and far past it the step is refused (never a hang)."""
    if events >= MAX_SWITCHES:
        raise model.StepRefused(f"switches more than {MAX_SWITCHES} times within one step "
                                "(chatter); reduce step_size")
    return events >= MAX_EVENTS_PER_STEP


def bounded(count: int) -> int:
    """A contact's sub-step count, or StepRefused past the planner's bound (never a hang)."""
    if count > stability.MAX_SUBSTEPS:
        raise model.StepRefused(f"needs more than {stability.MAX_SUBSTEPS} sub-steps while a "
                                "compliant limit is engaged to stay stable; reduce step_size "
                                "or the limit's stiffness and damping")
    return count


def fired(guard, kinds, y) -> list:
    """The switches whose functions went negative at y (q, q̇, extra), most negative first."""
    values = guard(*y)
    order = sorted(range(len(values)), key=values.__getitem__)
    return [kinds[n] for n in order if values[n] < 0.0]


def stopping_too(stepper, y, mode) -> list:
    """A sliding joint whose velocity reaches zero within TIME_TOLERANCE of a stop stops
    with it, to be settled together (worst first), not one at a time in an order rounding
    picks (while the other slid at 1e-100 rad/s). Those stopped here, as fired switches."""
    acceleration, too = stepper.functions(tuple(mode))[0](*y[:stepper.width]), []
    for j in (0, 1):
        u, a = y[2 + j], acceleration[j]
        if mode[j] in ("+", "-") and u * a < 0.0 and abs(u) <= abs(a) * TIME_TOLERANCE:
            y[2 + j], mode[j] = 0.0, "stuck"
            too.append(("stop", j))
    return too


def impulse(stepper, y, mode, i, located) -> None:
    """Joint i arrives at a hard limit: q̇ᵢ -> −e q̇ᵢ by an impulse along it (a slow
    bounce, or one past the step's quota, ends at rest); the other joint's velocity changes
    through M's coupling unless it rests on a limit the impulse pushes it into (past the
    quota: any limit it rests on, or two resting joints would kick each other off their
    stops for ever). The kinetic energy lost is booked."""
    j, limits = 1 - i, stepper.limits
    v = y[2 + i]
    if y[i] >= limits.upper[i] or y[i] <= limits.lower[i]:   # past or on a stop: that one,
        upper = y[i] >= limits.upper[i]      # whichever way a velocity of rounding's size points
    else:                                    # a hair before one: the one it moves to
        upper = v > 0.0 if v else y[i] > 0.5 * (limits.lower[i] + limits.upper[i])
    if not located or not limits.lower[i] <= y[i] <= limits.upper[i]:
        y[i] = limits.upper[i] if upper else limits.lower[i]   # late, or past by rounding
    bounce = not stepper.plastic and limits.restitution * abs(v) >= REST_SPEED
    e = limits.restitution if bounce else 0.0
    m11, m12, m22 = model.mass_matrix(stepper.arm, y[:2])
    diagonal, other = (m11, m22) if i == 0 else (m22, m11)
    coupling = -m12 / other                       # Δq̇ⱼ / Δq̇ᵢ for an impulse along i
    held = mode[j] in ("lower", "upper") and (
        stepper.plastic or (coupling * -v > 0) == (mode[j] == "upper"))
    if held:                 # both joints' stops take the impulse (chatter: both rest)
        coupling, inverse = 0.0, 1.0 / diagonal
    else:
        inverse = other / (m11 * m22 - m12 * m12)   # (M⁻¹)ᵢᵢ
    change = -(1.0 + e) * v
    y[2 + i] = -e * v if e else 0.0
    if coupling:              # the other joint moves (off its stop, if it pulls it away)
        y[2 + j] += coupling * change
        if stepper.friction is not None:
            mode[j] = "+" if y[2 + j] > 0 else "-" if y[2 + j] < 0 else "stuck"
        elif mode[j] in ("lower", "upper"):
            mode[j] = "free"
    if stepper.impact_at is not None:
        y[stepper.impact_at] += 0.5 * (1.0 - e * e) * v * v / inverse
    if e:
        mode[i] = ("-" if upper else "+") if stepper.friction is not None else "free"
    else:
        mode[i] = "upper" if upper else "lower"


def release(stepper, mode, i, y, lam) -> tuple:
    """`mode` with joint i freed: a stuck joint slips toward the net torque lam (onto a hard
    limit it rests against), a resting one comes free."""
    codes = list(mode[:2])
    if codes[i] == "stuck":
        up = lam < 0.0                        # slips toward the net torque
        limits = stepper.limits
        at = stepper.hard and (y[i] >= limits.upper[i] if up else y[i] <= limits.lower[i])
        codes[i] = ("upper" if up else "lower") if at else ("+" if up else "-")
    else:
        codes[i] = "stuck" if stepper.friction is not None else "free"
    return (*codes, *mode[2:])


def initial_mode(stepper, y) -> tuple:
    """The mode a state y starts in (a joint at rest on a hard limit rests there)."""
    codes, zones = [], [0, 0]
    for i in (0, 1):
        q, u, code = y[i], y[2 + i], "free"
        if stepper.friction is not None:
            code = "+" if u > 0 else "-" if u < 0 else "stuck"
        if stepper.hard and u == 0.0 and q >= stepper.limits.upper[i]:
            code = "upper"
        elif stepper.hard and u == 0.0 and q <= stepper.limits.lower[i]:
            code = "lower"
        elif stepper.limits is not None and not stepper.hard:
            zones[i] = 1 if q > stepper.limits.upper[i] else -1 if q < stepper.limits.lower[i] else 0
        codes.append(code)
    return stepper.clamps.initial((*codes, *zones)) if stepper.clamps else (*codes, *zones)
