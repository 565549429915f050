"""The control loop: the drive's law evaluated at the readings, and the command delay.

Scene: `command_delay: 0.001` (s, a whole number of steps; default 0): a torque or
set-point given at t acts from t + command_delay.

A drive that reads the state (a servo, a gravity-compensating policy) under sensors that
model something, and any commanding drive (a servo, the command policies) under a command
delay, runs as a sampled controller: at the start of each of its samples (every step; a
servo with its own rate every 1/rate, which must then be a whole number of steps) it reads
the reading in force (attach.py; the state itself where the sensors model nothing), the
command and set-points held, and computes its torque by its own law: the servo's discrete
law with its integrals stepped by forward Euler (effects/servo.py), the policy's torque
with the controller model's gravity (effects/actuator.py). That torque acts from
command_delay later and is held until the next acts: a command given at t acts from
t + command_delay, in order, none lost. The step's code reads the acting torque as a
command policy reads its command: a constant within the step (RK4 keeps its order, the
compiled step takes it), its power booked as `work`, so the books close as without sensors.
The shadow of the global error estimate (trust/shadow.py) has a controller of its own: it
reads the motion's reading moved by how far the shadow is from the motion (the counts and
draws the motion read, the feedback its own), steps its own integrals and delays its own
torque, so that an arm the loop holds up, unstable without it, does not pull the two apart.

Before t = command_delay the torque the law asks at t = 0 acts: the arm was held in its
initial state until then. A live change of command_delay applies to what is computed from
then on; what is in flight acts when it was due. A longer delay holds the acting torque
until the new delay has passed; after a shorter one the torques computed meanwhile wait
behind those in flight and only the latest acts, unless one was computed from a new command
or set-point: that one acts for a step at least, so none is lost.
"""
from __future__ import annotations

from collections import deque

from ..effects.servo import Servo, advanced_under
from .sensors import delay_steps


class Loop:
    """A drive (the effect whose `acting` the code reads) sampled, and its delay line of
    (step it acts from, torque, computed from new inputs)."""

    def __init__(self, dynamics, scene, carried: Loop | None = None):
        self.acting, self.given = dynamics.command, dynamics.given
        self.drive = next(e for e in dynamics.active if getattr(e, "acting", None) is not None)
        self.servo = self.drive if isinstance(self.drive, Servo) else None
        self.delay = delay_steps("command_delay", scene.command_delay, scene.step_size)
        self.every = 1
        if self.servo is not None:      # its rate a whole number of steps (attach.check)
            self.every = self.servo.every or 1
            self.servo.period = self.servo.period or scene.step_size
        self.line = None                 # until reset, or the first step after a live start
        self.shadow_acting = list(self.acting)    # the shadow's torque (beside)
        if carried is not None:          # a live change: what is in flight goes on
            self.line, self.inputs = carried.line, carried.inputs
            self.acting[:], self.shadow_acting = carried.acting, carried.shadow_acting

    def reset(self, state, reading) -> None:
        """At t = 0: the law's torque there acts until the first computed one does."""
        self.inputs = self._inputs()
        torque = (tuple(self.servo.law((*reading, *state[4:]), torque_only=True))
                  if self.servo is not None else tuple(self.drive.law(reading[0:2])))
        self.line = deque([(-1, torque, False, torque)])
        self.acting[:] = self.shadow_acting[:] = torque

    def before(self, sim, reading) -> None:
        """At the start of step sim.steps: a sample of the controller when one is due, and
        the torque that acts over the step."""
        if self.line is None:            # started live: what the law asks now acts until
            self.reset(sim.state, reading)   # the first computed torque does
        n, line = sim.steps, self.line
        if n % self.every == 0:
            inputs = self._inputs()
            torque = self._law(sim, reading)
            line.append((max(n + self.delay, line[-1][0]), torque, inputs != self.inputs,
                         self._shadow_law(sim, reading, torque)))
            self.inputs = inputs
        while len(line) > 1 and line[1][0] <= n:
            line.popleft()
            if line[0][2]:               # computed from a new command: it acts, none lost
                break
        _, torque, _, self.shadow_acting[:] = line[0]
        if torque != tuple(self.acting):  # a new torque moves the local error at once: checked
            self.acting[:] = torque
            sim.accuracy.due = min(sim.accuracy.due, n)

    def beside(self, advance, f, z, h):
        """advance(f, z, h) under the shadow's torque (Shadow.follow: its `sampled`)."""
        return advanced_under(self.acting, self.shadow_acting, advance, f, z, h)

    def _inputs(self) -> tuple:
        return (*self.given, *(self.servo.setpoint if self.servo is not None else ()))

    def _law(self, sim, reading) -> tuple:
        """The drive's torque at `reading`; a servo's integrals stepped in sim's state."""
        if self.servo is None:
            return tuple(self.drive.law(reading[0:2]))
        state, torque = sim.state, [0.0, 0.0]
        stepped = self.servo.sample((*reading, *state[4:]), torque)
        if stepped[4:] != state[4:]:
            replace_state(sim, state, (*state[:4], *stepped[4:]))
        return tuple(torque)


    def _shadow_law(self, sim, reading, torque) -> tuple:
        """The shadow's torque: the law at the reading moved by the shadow's distance from
        the motion, its own integrals stepped; the motion's where it is not followed."""
        shadow = getattr(sim.accuracy, "shadow", None)
        z = shadow.start(sim.state) if shadow is not None else None
        if z is None:
            return torque
        shadow.sampled = self            # it steps beside the motion under its own torque
        moved = tuple(r + a - b for r, a, b in zip(reading, z, sim.state))
        if self.servo is None:
            return tuple(self.drive.law(moved[0:2]))
        own = [0.0, 0.0]
        shadow.shadow = (*z[:4], *self.servo.sample((*moved, *z[4:]), own)[4:])
        return tuple(own)


def replace_state(sim, old, new) -> None:
    """sim's state `old` becomes `new` (its controller's integrals stepped): the
    switching stepper's mode, the confirmed state and the shadow go on from it (the shadow
    with integrals of its own: Loop._shadow_law)."""
    sim.state = new
    if sim.switching is not None and sim.switching.last is old:
        sim.switching.last = new
    if sim._sound is old:
        sim._sound = new
    shadow = getattr(sim.accuracy, "shadow", None)
    if shadow is not None and shadow.last is old and shadow.shadow is not None:
        shadow.last = new
