"""A simulator's compiled steps and runs: Kernel (Simulator.step and Simulator.run in
compiled calls, the books held in arrays between them) and Steps (the step compiled for each
right-hand side met), from the modules build.py writes and loads.
"""
from __future__ import annotations

from math import isfinite

from ..stepping.stability import MAX_SUBSTEPS
from ..trust import accuracy
from ..trust.unestimated import Off
from ..effects.servo import servo_of
from .build import SET_POINTS, compilable, constants_of, energy_source, load, module_source
from .held import pack, unpack
from .sensed import Sensed


class Kernel:
    """A simulator's compiled Simulator.step and Simulator.run: the step, the shadow, the
    error books' checks and schedule and the divergence check in one call (kernels.run_books;
    a switching scene's run_switching in its current mode, switch_run.py), handing back to
    Python only where Python must speak; and its compiled residual. Between calls the books
    stay in the arrays (`held`, held.py): packing them costs more than the step, so they go
    back into Python's objects only when Python reads them or takes a step (settle)."""

    path = "compiled (numba)"

    def __deepcopy__(self, memo):   # machinery and scratch: nothing a step leaves behind
        return self

    def __init__(self, dynamics, step, plain: bool, sensing=None, energy=None):
        import numpy as np
        self.plain = plain        # runs of plain steps (no switches, no driver check)
        # sensors and a control loop acting between steps (sensed.py), or None
        sensed = sensing is not None and sensing.active
        energy = energy_source(dynamics) if energy is None else energy
        source, names = module_source(dynamics, step, sensed=sensed, energy=energy)
        self.module = load(source)
        self.sensed = Sensed(sensing, self.module) if sensed else None
        self.K = constants_of(names, {**dynamics.function.__globals__,
                                      **getattr(step, "constants", {}), **SET_POINTS})
        joint_servo = servo_of(dynamics)       # a continuous servo's set-points: into K
        self.setpoints = [] if joint_servo is None or joint_servo.discrete else [
            (2 + names.index(name), joint_servo.setpoint, k)
            for k, name in enumerate(SET_POINTS) if name in names]
        self.C = np.array([0.0, 0.0, *energy[1]])   # the residual's K
        width = 4 + len(dynamics.extra) + len(dynamics.channels)
        self.y, self.z, self.L, self.O, self.G, self.S, self.D, self.r = (
            np.zeros(width) for _ in range(8))      # r: the residual's, apart from the run's
        self.I, self.F = np.zeros(18, dtype=np.int64), np.zeros(16)
        self.T = np.zeros((0, 6))      # the rows of a trajectory asked for (none)
        self.command = dynamics.command
        self.switched = None      # a switching scene's runs in one mode (switch_run.py)
        self.held = None          # (run, K, more, books) whose books the arrays hold
        self.last = None          # the state the latest compiled call handed out
        self.sound = -1           # the step of the latest state it found sound

    def step(self, sim) -> bool:
        """Simulator.step in one compiled call; False where Python must take the step."""
        if (self.held is None or sim.state is not self.last) and not self.hold(sim):
            return False
        run, K, more, _ = self.held
        self.given(sim, K)
        self.F[4] = 0.0
        done, code, self.sound = run(self.y, self.z, self.L, self.O, self.G, self.S, self.I,
                                     self.F, K, self.C, 1, self.T, *more)
        if not done:
            self.settle(sim)
            return False
        sim.state = self.last = tuple(self.y.tolist())
        sim.steps += 1
        if code == 2:                     # its divergence check is Python's
            self.settle(sim)
            sim._check_divergence()
        else:
            sim._checked = (sim.state, float(self.F[4]))   # its |residual|
        return True

    def run(self, sim, left: int, largest: float):
        """(steps taken, largest |residual|) of Simulator.run without a callback: steps in
        one compiled call while nothing is to be said; the step Python must take (a switch,
        a driver, a new highest count, a fault ...) as Simulator.step, its residual
        compiled. With rows in T, each step's row of the trajectory (recorded)."""
        if (self.held is None or sim.state is not self.last) and not self.hold(sim):
            sim.step_in_python()
            self.record(sim, 0)
            return 1, max(largest, abs(self.residual(sim)))
        run, K, more, _ = self.held
        self.given(sim, K)
        self.F[4] = largest
        done, code, self.sound = run(self.y, self.z, self.L, self.O, self.G, self.S, self.I,
                                     self.F, K, self.C, left, self.T, *more)
        return self.after(sim, left, done, code, largest)

    def after(self, sim, left: int, done: int, code: int, largest: float):
        """Kernel.run after its compiled call took `done` of `left` steps and said `code`
        (the arrays hold what it left: rollouts/batched.py calls this for a row of many)."""
        if done:
            sim.state = self.last = tuple(self.y.tolist())
            sim.steps, largest = int(self.I[0]), float(self.F[4])
        if code == 2:                     # its divergence check is Python's
            self.settle(sim)
            sim._check_divergence()
            largest = max(largest, abs(self.residual(sim)))
            self.record(sim, done - 1)
        if code != 1 or done == left:
            return done, largest
        self.settle(sim)
        sim.step_in_python()
        self.record(sim, done)
        return done + 1, max(largest, abs(self.residual(sim)))

    def record(self, sim, row: int) -> None:
        """A step Python took (or checked) into row `row` of T, as recorded() writes one."""
        if len(self.T):
            self.T[row] = (*sim.state[:4], *sim.joint_torque())

    def given(self, sim, K) -> None:
        """The command given (and a control loop's inputs) into K before a compiled call; under
        a loop K holds the torque acting, which the loop sets."""
        for at, setpoint, k in self.setpoints:
            K[at] = setpoint[k]
        if self.sensed is None:
            K[0], K[1] = self.command
        else:
            self.sensed.refresh(sim.sensing)
            if not self.sensed.looped:
                K[0], K[1] = self.command

    def hold(self, sim) -> bool:
        """The simulator's books into the arrays for the compiled run of its next steps;
        False where the next step is Python's."""
        self.settle(sim)
        books = sim.accuracy
        if sim.diverged:
            return False
        if self.plain and smooth(books) and (self.sensed is None or
                                             self.sensed.ready(sim.sensing, books)):
            if self.sensed is not None:
                self.sensed.pack(sim.sensing, self.K)
            run = (self.module.run_books, self.K, self.sensed.more if self.sensed else ())
        elif self.sensed is not None or self.switched is None or (
                run := self.switched.ready(self, sim, books)) is None:
            return False
        pack(self, sim, books)
        self.held, self.last, self.sound = (*run, books), sim.state, sim.steps
        return True

    def reading(self, sim):
        """The sensors' reading now taken in the arrays a run holds (Sensed.read), or None:
        Python's (settled)."""
        return None if self.held is None or self.sensed is None else self.sensed.read(sim)

    def settle(self, sim) -> None:
        """The books the arrays hold back into Python's objects (nothing when none)."""
        if self.held is None:
            return
        run, K, _, books = self.held
        self.held = None
        unpack(self, sim, books, self.sound)
        if self.sensed is not None:
            self.sensed.unpack(sim.sensing, K)
        if run is not self.module.run_books:
            self.switched.landed(self, sim, books)

    def drop(self) -> None:
        """Forget the books the arrays hold (Python's objects were put back: WholeSteps)."""
        self.held = None

    def commanded(self, sim, answered: bool) -> bool:
        """A new command (`answered`: a new torque) while the books are held, taken in the
        arrays where they can (True): with the estimate off there is nothing to take (no
        check, no shadow); with it, the next step is checked, as set_command does, unless a
        new torque asks the shadow (shadow.answered: Python's). Else the books are settled
        (False), a switching scene's too, its clamps' modes being Python's to find again."""
        if self.held is None:
            return False
        if self.held[0] is not self.module.run_books or (
                answered and not isinstance(self.held[3], Off)):
            self.settle(sim)
            return False
        if not isinstance(self.held[3], Off):
            self.I[1] = min(int(self.I[1]), int(self.I[0]))
        return True

    def residual(self, sim) -> float:
        self.r[:] = sim.state
        return self.module.residual(self.r, self.C, sim.initial_energy, *sim.retired)


class Steps:
    """step(f, y, h) compiled for each right-hand side f it is given: the scene's, and each
    mode's of a switching scene (events.py steps them; dynamics.mode_functions gives their
    source), compiled when first met, the command read at each call."""

    __deepcopy__ = Kernel.__deepcopy__   # compiled steps and scratch: shared by copies

    path = "compiled (numba)"

    def __init__(self, dynamics, step):
        import numpy as np
        self.dynamics, self.python = dynamics, step
        self.y = np.zeros(4 + len(dynamics.extra) + len(dynamics.channels))
        self.command, self.compiled, self.modules = dynamics.command, {}, {}

    def __call__(self, f, y, h):
        known = self.compiled.get(f)
        if known is None:
            known = self.compiled[f] = self.compile(f)
        step, K = known
        K[0], K[1] = self.command
        self.y[:] = y
        new = step(self.y, h, K)
        total = sum(new)
        if total - total == 0.0 or all(isfinite(v) for v in new):   # inf - inf, NaN: NaN
            return new
        # left the doubles: Python's step, the same numbers, says how (an exception where
        # Python's cos(inf) raises, where numba's makes NaN), as on the pure-Python path
        return self.python(f, tuple(y), h)

    def compile(self, f):
        """(step_array, K) of the module of rhs f; a function without source: Python's."""
        source = None if f is self.dynamics.function else getattr(f, "source", None)
        if source is None and f is not self.dynamics.function:
            return (lambda y, h, K: self.python(f, tuple(y), h)), [0.0, 0.0]
        text, names = module_source(self.dynamics, self.python, rhs=source,
                                    guards=getattr(f, "guards_source", ""))
        values = {**self.dynamics.function.__globals__, **getattr(self.python, "constants", {})}
        module, K = load(text), constants_of(names, values)
        self.modules[f] = module
        return module.step_array, K

    def module(self, f):
        """(the compiled module of a mode's rhs f, its K): its step and switching run."""
        if f not in self.compiled:
            self.compiled[f] = self.compile(f)
        return self.modules.get(f), self.compiled[f][1]


def steps_for(dynamics, step):
    """The compiled Steps of a fixed-step scene, or `step` itself (no numba, adaptive)."""
    if not compilable(dynamics, step):
        return step
    return Steps(dynamics, step)


def kernel_for(dynamics, step, stepped_elsewhere=None, sensing=None, servo=False):
    """The compiled kernel of a scene, or None (no numba, ARM_SIM_COMPILED=0, an adaptive
    step, or an effect whose stored energy has no compiled form); `stepped_elsewhere`
    (switches located, a driver checked step by step): its residual only; `sensing`: the
    sensors and control loop its runs take (sensed.py); `servo`: a continuous servo's scene
    too (build.compilable)."""
    energy = compilable(dynamics, step, servo) and energy_source(dynamics)
    if not energy:
        return None
    return Kernel(dynamics, step, stepped_elsewhere is None, sensing, energy)


def smooth(books) -> bool:
    """Books kernels.run_books takes on a smooth scene: the error books at the planned count,
    or none at all (estimate off, a count the stability plan takes)."""
    if isinstance(books, Off):
        return books.stepper is None and books.substeps <= MAX_SUBSTEPS
    return isinstance(books, accuracy.Accuracy) and books.stepper is None and \
        books.free.n == books.substeps
