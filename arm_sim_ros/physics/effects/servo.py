"""Joint servos: a PID per joint turns a position or velocity set-point into the joint torque.

Scene: `servo: {interface: [position, velocity], kp: [..], ki: [..], kd: [..]}`, optional
`velocity_kp`, `velocity_ki` (a velocity joint's own gains), `integral_limit` (N m) and
`tracking` (1/s). Per joint i, with the set-points qᵢ*, q̇ᵢ*:

- position: eᵢ = qᵢ* − qᵢ,  rᵢ = kpᵢ eᵢ + kdᵢ (q̇ᵢ* − q̇ᵢ) + clamp(wᵢ, ±Wᵢ)
- velocity: eᵢ = q̇ᵢ* − q̇ᵢ, rᵢ = kpᵢ eᵢ + clamp(wᵢ, ±Wᵢ) with the velocity gains (velocity_kp,
  velocity_ki; else kp, ki) and no kd (it would act on the acceleration the torque causes)
- effort:   rᵢ = the commanded torque (the command policies) or the scene's `setpoint`

plus the believed gravity torque under command_gravity_compensation (feed-forward). The
request is clamped to the effort limits, τᵢ = clamp(rᵢ, ±eᵢ), here (the servo replaces the
effort_limits effect, whose clamp it needs for its anti-windup), then drives the joint, or
with motor windings the driver, which turns it into the voltage Vᵢ = Rᵢ τᵢ / (Nᵢ kᵢ)
(motors.py). The integral torque wᵢ is an extra state integrated at the RK stages like a
winding current:

    dwᵢ/dt = kiᵢ eᵢ + bᵢ (τᵢ − rᵢ) + bᵢ (clamp(wᵢ, ±Wᵢ) − wᵢ)

the back-calculation anti-windup (Åström & Hägglund): while the effort limit cuts the
request, or the integral is past its clamp, wᵢ is pulled back at the tracking rate bᵢ
(default kiᵢ/kpᵢ: the tracking time is the integral time). Both terms are continuous in the
state, so RK4 needs no event. The servo is the actuator: its power τᵀq̇ is booked as `work`
(an input; a transfer through windings, whose electrical input is the input then), so the
energy books close as with any policy. It stores no energy.

With a `rate` (Hz) the servo is a discrete controller with zero-order hold: at each sample
t_k = k T (T = 1/rate, from t = 0) it reads q, q̇ and the set-points, computes τ_k by the
same law (the derivative term on the sampled velocity, as above), holds it until t_k+1, and
steps its integral by forward Euler, wᵢ += T (kiᵢ eᵢ + bᵢ (τᵢ − rᵢ + clamp(wᵢ) − wᵢ)) (the
discrete back-calculation). A sample inside a step splits the step there (sampled_step), so
within each piece the torque is a constant and RK4 keeps its order; the integrals stay in
the state (their rate 0 between samples) and the held torque is the `work` as before.
Under a control loop (physics/sensing/loop.py) the loop takes the samples, at the readings.
"""
from __future__ import annotations

from fractions import Fraction
from math import ceil, isfinite, pi, sqrt

from ..model import ParameterError, mass_matrix
from ..stepping.stability import worst_stiffness
from .actuator import ACTING, Actuator
from .base import Parameter

INTERFACES = ("position", "velocity", "effort")
MAX_SAMPLES_PER_STEP = 100   # a discrete servo's samples in one step, each splitting it
SERVO_POLICIES = ("setpoint", "command", "command_gravity_compensation")


class Servo(Actuator):
    name = "servo"
    parameters = (
        Parameter("interface", "names", "position|velocity|effort", default=("position",) * 2,
                  description="what each joint is commanded in", choices=INTERFACES),
        Parameter("kp", "pair", "N m/rad or N m s/rad", "non-negative",
                  description="proportional gain on the position (velocity) error"),
        Parameter("ki", "pair", "N m/(rad s) or N m/rad", "non-negative", default=(0.0, 0.0),
                  description="integral gain"),
        Parameter("kd", "pair", "N m s/rad", "non-negative", default=(0.0, 0.0),
                  description="derivative gain on the velocity error (position joints)"),
        Parameter("velocity_kp", "pair", "N m s/rad", "non-negative", default=None,
                  description="proportional gain of a velocity joint (none = kp)"),
        Parameter("velocity_ki", "pair", "N m/rad", "non-negative", default=None,
                  description="integral gain of a velocity joint (none = ki)"),
        Parameter("integral_limit", "pair", "N m", "positive", default=None,
                  description="largest integral torque (none = only the anti-windup)"),
        Parameter("tracking", "pair", "1/s", "positive", default=None,
                  description="anti-windup back-calculation rate (none = ki/kp)"),
        Parameter("rate", "float", "Hz", "positive", default=None,
                  description="sample rate of a discrete servo with zero-order hold "
                              "(none = continuous)"),
    )

    def __init__(self, interface=("position", "position"), kp=(0.0, 0.0), ki=(0.0, 0.0),
                 kd=(0.0, 0.0), velocity_kp=None, velocity_ki=None, integral_limit=None,
                 tracking=None, rate=None, *, policy="setpoint", setpoint=(0.0, 0.0),
                 initial_positions=(0.0, 0.0), effort_limits=None, command=None,
                 compensation=None, work_kind="input", believed="g", step_size=None):
        if policy not in SERVO_POLICIES:
            raise ParameterError(f"servo needs policy {', '.join(SERVO_POLICIES)}, not "
                                 f"{policy!r}")
        self.interface = tuple(interface)
        # each joint the gains of its interface (a switch back finds them): velocity, no kd
        on_velocity = [kind == "velocity" for kind in interface]
        self.kp = tuple(v if on else p for on, p, v in zip(on_velocity, kp, velocity_kp or kp))
        self.ki = tuple(v if on else i for on, i, v in zip(on_velocity, ki, velocity_ki or ki))
        self.kd = tuple(0.0 if on else d for on, d in zip(on_velocity, kd))
        self.integral_limit, self.effort_limits = integral_limit, effort_limits
        self.tracking = tracking or tuple(i / p if i > 0 and p > 0 else 1.0
                                          for i, p in zip(self.ki, self.kp))
        self.policy, self.compensation, self.work_kind = policy, compensation, work_kind
        self.compensates = policy == "command_gravity_compensation"
        self.believed, self.fixed, self.acting = believed, None, None
        self.command = command if command is not None else [0.0, 0.0]
        # [q1*, q2*, q̇1*, q̇2*, τ1*, τ2*]: read at every stage, written between steps
        self.setpoint = [*initial_positions, 0.0, 0.0, 0.0, 0.0]
        if policy == "setpoint":
            for i, (kind, value) in enumerate(zip(interface, setpoint)):
                self.setpoint[{"position": 0, "velocity": 2, "effort": 4}[kind] + i] = value
        self.state = ("integral1", "integral2")
        # a discrete servo (the scene's: step_size known): its grid, the torque it holds
        timed = rate is not None and step_size is not None
        self.rate, self.held, self.period = rate, [0.0, 0.0], 1.0 / rate if rate else None
        self.every, self.grid = sample_grid(rate, step_size) if timed else (None, None)
        self.shadow_held = [0.0, 0.0]    # what it holds in the error books' shadow (shadow.py)

    @property
    def discrete(self) -> bool:     # sampled: by its rate, or by a control loop
        return bool(self.rate) or self.acting is not None

    def constants(self, arm) -> dict:
        if self.acting is not None:
            return {"command": self.acting}
        out = {"command": self.command, "SP": self.setpoint} | (
            {"HELD": self.held} if self.rate else {})
        for i in (0, 1):
            j = i + 1
            out |= {f"KP{j}": self.kp[i], f"KI{j}": self.ki[i], f"KD{j}": self.kd[i],
                    f"KB{j}": self.tracking[i]}
            if self.integral_limit is not None:
                out[f"WLIM{j}"] = self.integral_limit[i]
            if self.effort_limits is not None:
                out[f"EFFORT{j}"] = self.effort_limits[i]
        return out

    def terms(self) -> list[str]:
        if self.discrete:           # held since the latest sample: a constant in the step
            return [ACTING] if self.acting is not None else ["t1 = HELD[0]", "t2 = HELD[1]"]
        lines = []
        for i in (0, 1):
            j, kind = i + 1, self.interface[i]
            lines.append(f"wc{j} = MIN(MAX(integral{j}, -WLIM{j}), WLIM{j})"
                         if self.integral_limit is not None else f"wc{j} = integral{j}")
            if kind == "position":
                lines += [f"e{j} = SP[{i}] - q{j}",
                          f"r{j} = KP{j} * e{j} + KD{j} * (SP[{2 + i}] - u{j}) + wc{j}"]
            elif kind == "velocity":
                lines += [f"e{j} = SP[{2 + i}] - u{j}", f"r{j} = KP{j} * e{j} + wc{j}"]
            else:
                held = f"SP[{4 + i}]" if self.policy == "setpoint" else f"command[{i}]"
                lines += [f"e{j} = 0.0", f"r{j} = {held}"]
            if self.compensates:
                lines.append(f"r{j} += {self.believed}{j}")
            lines.append(f"ts{j} = MIN(MAX(r{j}, -EFFORT{j}), EFFORT{j})"
                         if self.effort_limits is not None else f"ts{j} = r{j}")
            lines.append(f"t{j} = ts{j}")
        return lines

    def rates(self) -> list[str]:
        # no integral action (ki = 0, an effort joint): the integral stays where it is
        return [f"KI{j} * e{j} + KB{j} * (ts{j} - r{j} + wc{j} - integral{j})"
                if self.interface[j - 1] != "effort" and self.ki[j - 1] > 0 and not self.discrete
                else "0.0" for j in (1, 2)]    # a discrete servo's: stepped at its samples

    def stiffness(self, arm) -> float:
        if self.discrete:           # a constant torque within the step: nothing to resolve
            return 0.0
        # Velocity feedback (kd on a position joint, kp on a velocity joint) is a damper;
        # the back-calculation a decay of the integral at rate b.
        damping = max(kd if kind == "position" else kp if kind == "velocity" else 0.0
                      for kind, kp, kd in zip(self.interface, self.kp, self.kd))
        return damping * worst_stiffness(arm) + max(self.tracking)

    def frequency(self, arm) -> float:
        if self.discrete:
            return 0.0
        # kp on a position joint (ki on a velocity joint) is a spring; ki on a position joint
        # adds a slower third pole, bounded by the same spring scale.
        spring = max((kp if kind == "position" else ki if kind == "velocity" else 0.0)
                     + (ki if kind == "position" else 0.0)
                     for kind, kp, ki in zip(self.interface, self.kp, self.ki))
        return (spring * worst_stiffness(arm)) ** 0.5

    def law(self, state, torque_only=False) -> list:
        """Per joint (eᵢ, rᵢ, clamp(wᵢ), τᵢ): the continuous law at `state` (q, q̇, integrals
        first) with the set-points now; `torque_only`: the τᵢ alone."""
        q, u, w = state[0:2], state[2:4], state[4:6]
        g = self.compensation(q) if self.compensates else (0.0, 0.0)
        out = []
        for i, kind in enumerate(self.interface):
            wc = w[i] if self.integral_limit is None else min(max(w[i], -self.integral_limit[i]),
                                                               self.integral_limit[i])
            e = (self.setpoint[i] - q[i] if kind == "position" else
                 self.setpoint[2 + i] - u[i] if kind == "velocity" else 0.0)
            r = (self.kp[i] * e + self.kd[i] * (self.setpoint[2 + i] - u[i]) + wc
                 if kind == "position" else self.kp[i] * e + wc if kind == "velocity"
                 else self.setpoint[4 + i] if self.policy == "setpoint" else self.command[i]) + g[i]
            limit = self.effort_limits[i] if self.effort_limits is not None else float("inf")
            out.append((e, r, wc, min(max(r, -limit), limit)))
        return [t for *_, t in out] if torque_only else out

    def requested_torque(self, state):
        """τᵢ = clamp(rᵢ, ±eᵢ) at `state` (q, q̇, integrals first), as the servo asks now (a
        discrete servo: what it holds; under a control loop: what acts now)."""
        if self.acting is not None:
            return tuple(self.acting)
        return tuple(self.held if self.rate else self.law(state, torque_only=True))

    def sample(self, state, held) -> tuple:
        """A discrete servo's sample at `state`: τ_k into `held` from now, the state with the
        integrals stepped over the period (forward Euler of their continuous rate)."""
        state, law = list(state), self.law(state)
        for i, (e, r, wc, torque) in enumerate(law):
            held[i] = torque
            if self.interface[i] != "effort" and self.ki[i] > 0:
                back = self.tracking[i] * (torque - r + wc - state[4 + i])    # anti-windup
                state[4 + i] += self.period * (self.ki[i] * e + back)
        return tuple(state)

    def samples_in(self, n: int) -> tuple[bool, list]:
        """(whether a sample falls at the start of step n, the offsets in s from that start
        of those inside it); exact: rate and step size as the decimals they were written."""
        if self.every is not None:                     # a whole number of steps per sample
            return n % self.every == 0, []
        h, rate = self.grid
        start = n * h * rate                           # in sample periods
        first = ceil(start)
        inside = [float(k / rate - n * h)
                  for k in range(first + (first == start), ceil((n + 1) * h * rate))]
        return first == start, inside

    def beside(self, advance, f, z, h):
        """advance(f, z, h) under the shadow's held torque: the shadow follows the true motion,
        whose servo samples the true state, not the motion's."""
        return advanced_under(self.held, self.shadow_held, advance, f, z, h)

    def hold(self, q, joints=(0, 1)) -> None:
        """Set-points from the state: a position joint holds `q`, a velocity joint stops."""
        for i in joints:
            self.setpoint[i], self.setpoint[2 + i] = q[i], 0.0

    def bumpless(self, state, torque) -> tuple:
        """The integrals that make the servo ask for `torque` (what the joints received) at
        `state`, its set-points just taken from that state: a switch without a jump."""
        q, u = state[0:2], state[2:4]
        g = self.compensation(q) if self.compensates else (0.0, 0.0)
        integrals = []
        for i, kind in enumerate(self.interface):
            rest = (self.kd[i] * (self.setpoint[2 + i] - u[i]) if kind == "position" else
                    self.kp[i] * (self.setpoint[2 + i] - u[i]) if kind == "velocity" else None)
            if rest is None or self.ki[i] == 0.0:      # no integral action to carry it
                integrals.append(0.0)
                continue
            w = torque[i] - g[i] - rest - (self.kp[i] * (self.setpoint[i] - q[i])
                                           if kind == "position" else 0.0)
            if self.integral_limit is not None:
                w = min(max(w, -self.integral_limit[i]), self.integral_limit[i])
            integrals.append(w)
        return tuple(integrals)


def advanced_under(torque: list, other, advance, f, z, h):
    """advance(f, z, h) with the list the generated code reads a torque from (`torque`) holding
    `other` meanwhile: the error estimate's shadow stepped under its own torque."""
    mine = torque[:]
    torque[:] = other
    try:
        return advance(f, z, h)
    finally:
        torque[:] = mine


def sample_grid(rate: float, step_size: float) -> tuple:
    """(steps per sample when that is a whole number, else None; (step size, rate) as exact
    fractions of the decimals they were written as), or one line refusing the rate."""
    if not rate * step_size >= 1e-9:
        raise ParameterError(f"servo.rate = {rate:g} Hz samples less than once in 1e9 steps "
                             f"of {step_size:g} s; leave it out for a continuous servo")
    if rate * step_size > MAX_SAMPLES_PER_STEP:
        raise ParameterError(f"servo.rate = {rate:g} Hz samples {rate * step_size:g} times in "
                             f"each step of {step_size:g} s, each splitting it; at most "
                             f"{MAX_SAMPLES_PER_STEP}: lower the rate or the step_size")
    h, rate = (Fraction(v).limit_denominator(10**9) for v in (step_size, rate))
    per_sample = 1 / (h * rate)
    return (int(per_sample) if per_sample.denominator == 1 else None), (h, rate)


def sampling_risk(joint_servo: Servo, arm) -> str:
    """'' or why a discrete servo's sampled loop diverges: its velocity feedback K (kd on a
    position joint, kp on a velocity joint) held for a period T moves q̇ by T M(q)⁻¹ K q̇,
    which overshoots for good once an eigenvalue passes 2 at some elbow angle."""
    k = [kd if kind == "position" else kp if kind == "velocity" else 0.0
         for kind, kp, kd in zip(joint_servo.interface, joint_servo.kp, joint_servo.kd)]
    worst = 0.0
    for n in range(65):              # M depends on cos q2 alone: q2 over [0, π]
        m11, m12, m22 = mass_matrix(arm, (0.0, pi * n / 64))
        det = m11 * m22 - m12 * m12  # M⁻¹ K: trace and determinant; real eigenvalues
        trace, product = (m22 * k[0] + m11 * k[1]) / det, k[0] * k[1] / det
        worst = max(worst, trace / 2 + sqrt(max(trace * trace / 4 - product, 0.0)))
    if worst * joint_servo.period <= 2.0:
        return ""
    return (f"servo.rate = {joint_servo.rate:g} Hz samples too slowly for its velocity gains: "
            f"T M(q)⁻¹ K reaches {worst * joint_servo.period:.3g} (beyond 2), so the sampled "
            f"loop diverges or limit-cycles; raise the rate above {worst / 2:.4g} Hz or lower "
            "the gains")


def sampled_step(sim, take, f):
    """take(f, y, h) over the simulator's next step, split at the discrete servo's samples in
    it, each taken there; one at the step's start first. Within each piece the torque is a
    constant and RK4 keeps its order."""
    at_start, inside = sim.sampled.samples_in(sim.steps)
    if at_start or inside:   # a new torque moves the local error at once: checked (as a
        take = sim.accuracy.check              # new command is, simulator.set_command)
    if at_start:
        sim.state = sample(sim, sim.state)
    y, done = sim.state, 0.0
    for offset in inside:
        y = take(f, y, offset - done)
        if not all(isfinite(v) for v in y):   # the simulator refuses the step: no sample
            return y
        y, done = sample(sim, y), offset
    return take(f, y, sim.step_size - done)


def sample(sim, y) -> tuple:
    """The discrete servo's sample at state y: the torque it holds until its next, and y with
    its integrals stepped (a state the switching stepper still follows: only integrals
    changed, which no mode and no right-hand side of a discrete servo reads). The error
    books' shadow samples its own state."""
    joint_servo, shadow = sim.sampled, sim.accuracy.shadow   # None: no global estimate
    sampled = joint_servo.sample(y, joint_servo.held)
    if sim.switching is not None and sim.switching.last is y:
        sim.switching.last = sampled
    z = None if shadow is None else shadow.start(y)
    if z is None:                  # not followed (yet), or none: the shadow is the motion
        joint_servo.shadow_held[:] = joint_servo.held
    else:
        shadow.shadow, shadow.last = joint_servo.sample(z, joint_servo.shadow_held), sampled
    if shadow is not None:
        shadow.sampled = joint_servo
    return sampled


def sampled(dynamics) -> Servo | None:
    """The scene's servo if it is a discrete one (a `rate`) sampling itself, else None."""
    joint_servo = servo_of(dynamics)
    return joint_servo if joint_servo is not None and joint_servo.rate and \
        joint_servo.acting is None else None


def servo_of(dynamics) -> Servo | None:
    """The scene's servo effect, None without one."""
    return next((e for e in dynamics.active if isinstance(e, Servo)), None)


def change_scene(sim, scene) -> None:
    """`sim.change_scene(scene)` with the servo's set-points carried over; a joint whose
    interface changed starts bumplessly: its set-points from the current state and the
    integral that keeps the torque it asks for (an effort joint: the command that does)."""
    old = servo_of(sim.dynamics)
    torque = old.requested_torque(sim.state) if old is not None else sim.joint_torque()
    sim.change_scene(scene)
    new = servo_of(sim.dynamics)
    if new is None:
        return
    if old is not None:
        new.setpoint[:] = old.setpoint
    switched = [i for i in (0, 1) if old is None or old.interface[i] != new.interface[i]]
    new.hold(sim.state[0:2], switched)
    new.held[:] = new.shadow_held[:] = torque     # a discrete servo: until its next sample
    # a rate changed (continuous <-> discrete): every joint's law now asks anew, so every
    # joint's integral is set for the torque it received (its set-points kept)
    retimed = switched if old is not None and old.rate == new.rate else [0, 1]
    integrals = new.bumpless(sim.state, torque)
    g = new.compensation(sim.state[0:2]) if new.compensates else (0.0, 0.0)
    state = list(sim.state)
    for i in retimed:
        if new.interface[i] == "effort":
            new.command[i] = new.setpoint[4 + i] = torque[i] - g[i]
        state[sim.state_names.index(f"integral{i + 1}")] = integrals[i]
    sim.state = tuple(state)


def interfaces(dynamics) -> tuple:
    """What each joint is commanded in: its servo's interface, else effort."""
    joint_servo = servo_of(dynamics)
    return joint_servo.interface if joint_servo is not None else ("effort", "effort")


def set_points(dynamics, setpoints: dict) -> None:
    """{(field, joint): value} into the servo's set-points (field position or velocity); a
    position without a velocity targets rest."""
    joint_servo = servo_of(dynamics)
    for (field, joint), value in setpoints.items():
        if field == "position":
            joint_servo.setpoint[joint] = value
            joint_servo.setpoint[2 + joint] = setpoints.get(("velocity", joint), 0.0)
        else:
            joint_servo.setpoint[2 + joint] = value


def hold(dynamics, state) -> None:
    """A command timed out: position joints hold where they are, velocity joints stop."""
    joint_servo = servo_of(dynamics)
    if joint_servo is not None:
        joint_servo.hold(state[0:2], [i for i in (0, 1) if joint_servo.interface[i] != "effort"])
