"""Time, state and energy accounting for one arm: step() / run(duration) / reset().

Simulated time is always steps x step_size, never an accumulated sum, so late callers
cannot make it skip or drift.

At the stability limit (stability.py) a step is split into equal sub-steps, and a step
that would leave the finite numbers is refused: the last finite state is kept and
`fault` says why; so is every step after a state that diverged while finite (guard.py:
energy from nothing, checked at every state as it is made), until reset. Both are
reported in `events`. A motor driver asked for more than its
voltage limit (checked at the state each step ends in) is counted in `saturated_steps`
and reported once, the first time, as a `saturation` event.
"""
from __future__ import annotations

from collections import Counter, deque
from functools import partial
from math import inf, isfinite, nan

from .trust import accuracy, guard
from .compiled import runs as compiled
from . import model
from .stepping import stability
from .switching.events import switching as switching_for
from .dynamics import book_entries, build_dynamics
from .effects import servo
from . import sensing
from .stepping.integrators import INTEGRATORS
from .stepping.exponential import step_for
from .stepping.generated import shared
from .scene import Scene, SceneError
from .compiled.switch_run import Switched
from .compiled.held import Settled, acting, settle
from .reports import Event, Sample

EVENT_LOG_LENGTH = 100     # recent events kept; listeners see every one
class Simulator:
    # the error books, energy in play, latest sound state: a compiled kernel holds them
    accuracy, energy_in_play, _sound = Settled(), Settled(), Settled()

    def __init__(self, scene: Scene):
        self.scene, self.step_size, self._tableau = scene, scene.step_size, INTEGRATORS[
            scene.method]
        self.events: deque = deque(maxlen=EVENT_LOG_LENGTH)
        self.event_listeners: list = []     # callables(Event), e.g. the Rerun sink
        self.steps = 0
        self._build(scene)
        self.reset()
        starts_finite(self)

    def _build(self, scene: Scene, command=None) -> None:
        """Dynamics, step and stability plan of `scene` (again after a payload change)."""
        self.scene, self.arm = scene, scene.arm
        self.dynamics, self._step = code_of(scene, command)
        self.channels, self.extra = self.dynamics.channels, self.dynamics.extra
        self.state_names = ("q1", "q2", "qd1", "qd2") + self.extra + self.channels
        self._rhs = self.dynamics.function
        self._inputs, self._losses = book_entries(self.dynamics)
        self.stability_ratio, self.stability_limit, self.substeps, message = stability.plan(
            self._tableau, self.dynamics.active, self.arm, self.step_size,
            whole=scene.stability_plan == "off")
        if message:
            self._emit("substepping", message)
        self._driver = self.dynamics.driver_check()    # None without a voltage limit
        steppers(self, scene)   # switches located, compiled steps, error books

    def reset(self) -> None:
        settle(self, keep=False)     # what a compiled kernel held is of the run before
        s = self.scene
        self.state = ((*s.initial_positions, *s.initial_velocities)
                      + (0.0,) * (len(self.extra) + len(self.channels)))
        self.steps = 0
        self.fault = None            # why the latest refused step was refused, None if none
        self.refused_steps, self._refused_step = 0, -1    # how many; the latest's index
        self.saturated_steps = 0     # steps ending where a driver asks beyond its voltage limit
        self.dynamics.given[:] = [0.0, 0.0]
        self.initial_energy = self.energy(self.state)
        self.diverged = None         # why the run diverged (guard.py), held until reset
        self.retired = (0.0, 0.0)    # (inputs, losses) of channels change_scene removed
        self._sound = self.state     # the latest state the divergence check found sound
        self._checked = (None, 0.0)  # (the latest state checked, its residual)
        self.energy_in_play = guard.in_play(self, self.state)   # the most seen (guard.py)
        self.books_fault = None      # why the energy books do not close, said once
        self.switch_events = self.switching.reset() if self.switching else Counter()  # by kind
        self.accuracy.reset()
        if self.sampled is not None:     # what the first sample will hold: no stale torque
            self.sampled.held[:] = self.sampled.law(self.state, torque_only=True)
        if self.sensing is not None: self.sensing.reset(self)   # noqa: E701 (sample 0)

    @property
    def time(self) -> float:
        return self.steps * self.step_size

    def set_command(self, tau1: float, tau2: float, setpoints=None) -> None:
        """The command and a servo's set-points, held until the next call (set_command)."""
        set_command(self, tau1, tau2, setpoints)

    def set_payload(self, mass: float) -> None:
        """Grasp (M(q) q̇ kept: an inelastic grasp of a mass at rest) or release (q̇ kept) a
        payload now; the energy that changes hands is booked in `payload_exchange`."""
        before, old, q, qd = self.energy(self.state), self.scene, self.state[0:2], self.state[2:4]
        self.change_scene(old.replace(payload={"mass": mass}))
        if mass > (old.payload or {"mass": 0.0})["mass"]:
            m11, m12, m22 = model.mass_matrix(old.arm, q)
            momentum = (m11 * qd[0] + m12 * qd[1], m12 * qd[0] + m22 * qd[1])
            qd = model.solve_mass_matrix(*model.mass_matrix(self.arm, q), *momentum)
        state = [*self.state[0:2], *qd, *self.state[4:]]
        state[self.state_names.index("payload_exchange")] += self.energy(state) - before
        self.state = self._sound = tuple(state)

    def change_scene(self, scene: Scene) -> None:
        """From the next step, `scene`'s effects; time, state and books kept (step size too)."""
        settle(self)
        carried, was = dict(zip(self.state_names, self.state)), self.books(self.state)
        self._build(scene, self.dynamics.given)
        self.state = self._sound = tuple(carried.get(n, 0.0) for n in self.state_names)
        self.retired = tuple(r + w - n for r, w, n in zip(self.retired, was, self.books(self.state)))

    substeps_taken = property(lambda self: self.accuracy.taken(self.steps))   # split steps
    readings = property(lambda self: readings(self))    # (q1, q2, q̇1, q̇2) as the sensors read

    @property
    def error_estimate(self) -> float:
        """The latest step's local error estimate, rad and rad/s (carried between checks)."""
        return self.accuracy.error_estimate

    @property
    def accumulated_error(self) -> float:
        """The global error estimate since reset: the largest distance of the motion from
        its shadow (shadow.py), rad and rad/s; NaN where steps are not estimated."""
        return self.accuracy.accumulated()

    @property
    def holding(self) -> bool:
        """True while the latest step was refused and the state is the last finite one."""
        return self.refused_steps > 0 and self._refused_step == self.steps - 1

    def step(self) -> None:
        """One step: in one compiled call where it can be (compiled/runs.py), else here."""
        if self.kernel is None or not self.kernel.step(self):
            self.step_in_python()

    def step_in_python(self) -> None:
        if self.diverged:                 # held until reset: what follows would be nonsense
            self._refuse(self.diverged, "the last sound state")
            self.steps += 1
            return
        if self.sensing is not None: self.sensing.before(self)   # noqa: E701 (sensing/)
        books = self.accuracy       # plain planned steps until a check is due: no wrapper
        take = books.plain if self.steps < books.due else books.check
        try:    # a discrete servo: the step split at its samples, each taken there
            y = take(self._rhs, self.state, self.step_size) if self.sampled is None else \
                servo.sampled_step(self, take, self._rhs)
        except (ValueError, OverflowError, ZeroDivisionError) as error:  # cos(inf), inf ** 2
            self._refuse(f"cannot be taken: {model.arithmetic_fault(error)}")
        else:
            total = sum(y)
            if total - total == 0.0 or all(isfinite(v) for v in y):  # inf - inf, NaN are NaN
                self.state = y
            else:
                self._refuse("would make " + ", ".join(
                    f"{n} = {v}" for n, v in zip(self.state_names, y) if not isfinite(v)))
        self.steps += 1
        if not self.holding:
            self._check_divergence()
        if self._driver is not None and not self.holding:
            saturation(self)

    def _check_divergence(self) -> None:
        """A diverged state (guard.py) gives way to the last sound one, held until reset."""
        residual = self.residual()
        why = guard.divergence(self, self.state, residual)
        if why is None:
            self._sound, self._checked = self.state, (self.state, residual)
            if guard.audit(self, residual):    # books that do not close: said once
                self._emit("books", self.books_fault)
        else:                             # the step just counted is refused after all
            self.state, self.diverged = self._sound, why
            self._refuse(why, "the last sound state", self.steps - 1)

    def _refuse(self, why: str, kept: str = "the last finite state", step=None) -> None:
        step = self.steps if step is None else step
        self.fault = f"the step to t = {(step + 1) * self.step_size:.6g} s {why}; holding {kept}"
        if not self.refused_steps or self._refused_step != step - 1:   # the first of a run
            self._emit("fault", self.fault)
        self._refused_step = step
        self.refused_steps += 1

    def _emit(self, kind: str, message: str) -> None:
        event = Event(self.time, kind, message)
        self.events.append(event)
        for listener in self.event_listeners:
            listener(event)

    def energies(self, state) -> tuple[float, float]:
        return energies(self, state)     # (kinetic, stored), NaN where sin fails

    def energy(self, state) -> float:
        return sum(self.energies(state))

    def channel_values(self, state) -> dict:
        first = 4 + len(self.extra)
        return dict(zip(self.channels, state[first:first + len(self.channels)]))

    def books(self, state) -> tuple[float, float]:
        """(Σ input channels, Σ loss channels) carried in a state, retired ones included."""
        return (sum((state[i] for i in self._inputs), self.retired[0]),
                sum((state[i] for i in self._losses), self.retired[1]))

    def residual(self, state=None) -> float:
        """E - E(0) - inputs + losses of `state` (now): zero for an exact integration."""
        state = self.state if state is None else state
        work, dissipated = self.books(state)
        return self.energy(state) - self.initial_energy - work + dissipated

    def joint_torque(self, state=None) -> tuple[float, float]:
        """The torque the joints receive at `state` (now): after limits and windings."""
        if self.dynamics.command is not self.dynamics.given:   # a control loop's torque
            acting(self)
        return tuple(self.dynamics.joint_torque(self.state if state is None else state))

    def sample(self) -> Sample:
        return sample(self)

    def run(self, duration: float, on_step=None) -> float:
        """Advance by `duration` (whole steps); return the largest |residual| at any step."""
        left = steps = self.scene.steps_for(duration, self.step_size)
        largest, fast = 0.0, on_step is None and self.kernel is not None   # no callback
        while left:
            taken, largest = self.kernel.run(self, left, largest) if fast else (1, largest)
            if not fast:
                self.step()
                largest = max(largest, abs_residual(self))   # the check's where it made it
                if on_step is not None: on_step(self)   # noqa: E701 (the class's 200 lines)
            left -= taken
        return largest


def starts_finite(sim: Simulator) -> None:
    """SceneError (one line) where what sim starts from is not finite (guard.check_start)."""
    try:
        guard.check_start(sim)
    except model.ParameterError as error:
        raise SceneError(str(error)) from None


def code_of(scene: Scene, command=None) -> tuple:
    """(dynamics, step): the scene's generated right-hand side and its method's step, the
    text the compiled path compiles (arm-sim inspect --source prints it)."""
    dynamics, tableau = build_dynamics(scene, command), INTEGRATORS[scene.method]
    made = partial(step_for, tableau, len(dynamics.channels), dynamics.decay, rtol=scene.rtol,
                   atol=scene.atol)
    # a fixed step is a pure function, one per method and state (an adaptive step keeps its
    # last sizes: its own)
    return dynamics, made() if tableau.adaptive else shared(
        (scene.method, len(dynamics.channels), dynamics.decay), made)


def set_command(sim: Simulator, tau1: float, tau2: float, setpoints=None) -> None:
    """Simulator.set_command, servo `setpoints` {(field, joint): value}. A new command moves
    the local error at once: the next step is checked (accuracy.py), not the one the
    schedule had come to."""
    before, torque = commanded(sim), tuple(sim.dynamics.given)
    sim.dynamics.given[0] = tau1      # under a control loop: its input (sensing/loop.py)
    sim.dynamics.given[1] = tau2
    servo.set_points(sim.dynamics, setpoints or {})
    changed, answered = commanded(sim) != before, tuple(sim.dynamics.given) != torque
    if not (changed or answered) or (sim.kernel is not None and
                                     sim.kernel.commanded(sim, answered)):
        return                        # the kernel's arrays took it: no books to settle
    if changed:
        sim.accuracy.due = min(sim.accuracy.due, sim.steps)
    if answered and sim.accuracy.shadow is not None:
        sim.accuracy.shadow.answered()        # a controller's answer (shadow.py)


def commanded(sim: Simulator) -> tuple:
    """The command and a servo's set-points, as the step reads them."""
    joint_servo = servo.servo_of(sim.dynamics)
    return (*sim.dynamics.given, *(joint_servo.setpoint if joint_servo is not None else ()))


def abs_residual(sim: Simulator) -> float:
    """|sim.residual()| of the state now: the divergence check's where it made it (a
    compiled step hands it out; the node books it every tick), else computed."""
    checked, residual = sim._checked
    return abs(residual) if checked is sim.state else abs(sim.residual())


def saturation(sim: Simulator) -> None:
    """A driver asked for more than its voltage limit at the state the step ended in:
    counted, and said once."""
    over = sim._driver(sim.state)
    if over:
        sim.saturated_steps += 1
        if sim.saturated_steps == 1:
            sim._emit("saturation", f"motor driver saturates: {over}")


def steppers(sim: Simulator, scene: Scene) -> None:
    """What steps the simulator: the switching stepper (friction, limits, clamps: events.py),
    the compiled step and runs (compiled.py, extra `fast`), and the error books."""
    sim.lowest_energy = guard.lowest_energy(sim)      # where the energy in play starts
    step = compiled.steps_for(sim.dynamics, sim._step)
    sim.sensing = sensing.attach(sim, scene)   # readings and a control loop act between steps
    sim.switching = switching_for(sim.dynamics, sim._tableau, step, sim.substeps, sim._emit,
                                  lambda: sim.time, getattr(sim, "switch_events", None))
    sim.kernel = compiled.kernel_for(sim.dynamics, sim._step, sim.switching or sim._driver,
                                     sim.sensing)
    if sim.kernel is not None and sim.switching is not None and hasattr(step, "module"):
        sim.kernel.switched = Switched(step, sim._driver is not None)   # switch_run.py
    sim.path = getattr(step, "path", "python")
    sim.sampled = servo.sampled(sim.dynamics)    # a discrete servo (its rate), or None
    if sim.sampled is not None and (risk := servo.sampling_risk(sim.sampled, sim.arm)):
        sim._emit("servo", risk)
    sim.accuracy = books_for(sim, scene, step)   # the planned step, its error checked


def books_for(sim: Simulator, scene: Scene, step):
    """The error books (accuracy.py) of `step` (the simulator's, compiled where it can be),
    with the shadow's own switching stepper where the scene switches (it says nothing: its
    switches are not the run's; none with `estimate` off: no shadow)."""
    twin = sim.switching and scene.estimate != "off" and switching_for(
        sim.dynamics, sim._tableau, step, sim.substeps, lambda kind, message: None, lambda: 0.0)
    return accuracy.plan(sim._tableau, step, sim.substeps, scene.tolerance, 4, sim._emit,
                         lambda: sim.steps, sim.switching, getattr(sim, "accuracy", None),
                         int(scene.max_substeps), 4 + len(sim.extra), twin, scene.estimate,
                         sim.stability_ratio / (sim.stability_limit or inf),
                         stability.stiff_names(sim.dynamics.active, sim.arm) or "damping")


def energies(sim: Simulator, state) -> tuple[float, float]:
    """(kinetic, stored) of `state`; NaN where sin fails (angles near 1e308), not a crash."""
    q, qd, extra = state[0:2], state[2:4], state[4:4 + len(sim.extra)]
    try:
        stored = 0.0
        for effect in sim.dynamics.active:
            start = sim.extra.index(effect.state[0]) if effect.state else 0
            stored += effect.stored_energy(sim.arm, q, extra[start:start + len(effect.state)])
        return model.kinetic_energy(sim.arm, q, qd), stored
    except (ValueError, OverflowError):
        return nan, nan


def sample(sim: Simulator) -> Sample:
    """The arm and its energy books now."""
    y = sim.state
    kinetic, potential = sim.energies(y)
    channels = sim.channel_values(y)
    inputs, losses = sim.books(y)
    return Sample(t=sim.time, q=(y[0], y[1]), qd=(y[2], y[3]), tau=sim.joint_torque(y),
                  kinetic=kinetic, potential=potential, work=channels.get("work", 0.0),
                  dissipated=channels.get("dissipated", 0.0), initial_energy=sim.initial_energy,
                  extra=dict(zip(sim.extra, y[4:4 + len(sim.extra)])),
                  channels=channels, inputs=inputs, losses=losses,
                  measured=sim.readings if sim.scene.sensors is not None else None)


def readings(sim: Simulator) -> tuple:
    """(q1, q2, q̇1, q̇2) as the sensors read them now (physics/sensing/): the state's own
    without sensors that model something."""
    if sim.sensing is None:
        return tuple(sim.state[:4])
    read = sim.kernel and sim.kernel.reading(sim)     # in the arrays a compiled run holds
    if read is None:
        settle(sim)              # what a compiled run holds of them
        read = sim.sensing.reading(sim)
    return read


def recorded_row(sim) -> tuple:
    """What a recording keeps of a step: the state; with sensors, the readings after it;
    under a control loop (sensing/loop.py), the torque that acted over it."""
    looped = sim.dynamics.command is not sim.dynamics.given
    if looped:
        acting(sim)              # the torque acting, as a compiled run holds it
    row = sim.state + sim.readings if sim.scene.sensors is not None else sim.state
    return row + tuple(sim.dynamics.command) if looped else row
