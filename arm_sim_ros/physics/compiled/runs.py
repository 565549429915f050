"""A simulator's compiled runs: Kernel (kernels.run_books from the simulator's state and
books, and back into them) and Steps (the step compiled for each right-hand side met), from
the modules build.py writes and loads.
"""
from __future__ import annotations

from ..stepping.stability import MAX_SUBSTEPS
from ..trust import accuracy, guard
from ..trust.controller import SAFETY
from ..trust.unestimated import Off
from .build import compilable, constants_of, energy_source, load, module_source

NEVER = 2 ** 62           # the step index of a check that never comes (estimate off)


class Kernel:
    """A simulator's compiled Simulator.run (kernels.run_books: its steps, the shadow, the
    error books' checks and the divergence checks in one call) and its compiled residual."""

    path = "compiled (numba)"

    def __deepcopy__(self, memo):   # machinery and scratch: nothing a step leaves behind
        return self

    def __init__(self, dynamics, step, plain: bool):
        import numpy as np
        self.plain = plain        # runs of plain steps (no switches, no driver check)
        source, names = module_source(dynamics, step)
        self.module = load(source)
        self.K = constants_of(names, {**dynamics.function.__globals__,
                                      **getattr(step, "constants", {})})
        self.C = np.array([0.0, 0.0, *energy_source(dynamics)[1]])   # the residual's K
        width = 4 + len(dynamics.extra) + len(dynamics.channels)
        self.y, self.z, self.L, self.O, self.G, self.S, self.D = (np.zeros(width)
                                                                  for _ in range(7))
        self.I, self.F = np.zeros(18, dtype=np.int64), np.zeros(16)
        self.command, self.lowest = dynamics.command, None
        self.switched = None      # a switching scene's runs in one mode (switch_run.py)

    def run(self, sim, left: int, largest: float):
        """(steps taken, largest |residual|) of Simulator.run without a callback: steps in
        one compiled call while nothing is to be said; the step Python must take (a switch,
        a driver, a new highest count, a fault ...) as Simulator.step, its residual
        compiled."""
        books, done, code = sim.accuracy, 0, 1
        if self.plain and not sim.diverged and smooth(books):
            done, largest, code = self.books_run(sim, books, left, largest)
        elif self.switched is not None:   # a switching scene's steps in one mode
            done, largest, code = self.switched.run(self, sim, left, largest)
        if code == 2:                     # its divergence check is Python's
            sim._check_divergence()
            largest = max(largest, abs(self.residual(sim)))
        if code != 1 or done == left:
            return done, largest
        sim.step()
        return done + 1, max(largest, abs(self.residual(sim)))

    def residual(self, sim) -> float:
        self.y[:] = sim.state
        return self.module.residual(self.y, self.C, sim.initial_energy, *sim.retired)

    def books_run(self, sim, books, left: int, largest: float, run=None, K=None, more=()):
        """kernels.run_books (or `run`, reading K and `more`) from the simulator's state
        and books, and back into them."""
        I, F, h = self.I, self.F, sim.step_size
        run, K = run or self.module.run_books, self.K if K is None else K
        K[0], K[1] = self.command
        self.y[:] = sim.state
        if self.lowest is None:
            self.lowest = guard.lowest_energy(sim)
        if isinstance(books, Off):        # the steps alone: no check is ever due
            n = books.substeps
            I[:] = (sim.steps, NEVER, sim.steps, 0, n, 1, n, n, n, n, 1, 4, 4, 0, 0, 0, 1,
                    sim.books_fault is not None)
            F[:] = (h, sim.initial_energy, *sim.retired, largest, 0.0, sim.energy_in_play,
                    books.error_estimate, 1.0, 0.0, 1.0, 1.0, 1.0, self.lowest, 4.0, 0.0)
            done, code, sound = run(self.y, self.z, self.L, self.O, self.G, self.S, I, F, K,
                                    self.C, left, *more)
            return self.landed(sim, done, code, sound, largest)
        shadow, n = books.shadow, books.states
        known = shadow.local is not None
        followed = known and not shadow.lost and sim.state is shadow.last
        if known:
            self.L[:n] = shadow.local
        if followed:
            self.z[:] = shadow.shadow
        self.O[:n] = shadow.offset or [0.0] * n
        I[:] = (sim.steps, books.due, books.since, books.booked_taken, books.substeps,
                books.every, books.free.floor, books.free.cap, books.cap, books.most,
                books.capped, n, books.order, known, followed, shadow.lost,
                books.said_lost or books.emit is None, sim.books_fault is not None)
        F[:] = (h, sim.initial_energy, *sim.retired, largest, shadow.largest,
                sim.energy_in_play, books.error_estimate, books.free.previous, books.tolerance,
                SAFETY * books.target(h), books.target(h), books.factor, self.lowest,
                float(books.order), books.stiff_below)
        done, code, sound = run(self.y, self.z, self.L, self.O, self.G, self.S, I, F, K,
                                self.C, left, *more)
        if not done:
            return 0, largest, code
        books.due, books.since, books.booked_taken = (int(v) for v in I[1:4])
        if int(I[4]) != books.substeps:
            books.use(int(I[4]))
        books.every = int(I[5])
        books.error_estimate, books.free.previous = float(F[7]), float(F[8])
        if I[13]:
            shadow.local = self.L[:n].tolist()
        if I[14]:
            shadow.shadow, shadow.offset = tuple(self.z.tolist()), self.O[:n].tolist()
        shadow.largest, shadow.lost = float(F[5]), bool(I[15])
        taken = self.landed(sim, done, code, sound, largest)
        if I[14]:
            shadow.last = sim.state
        return taken

    def landed(self, sim, done: int, code: int, sound: int, largest: float):
        """The run's state, step count, energy in play and latest sound state into the
        simulator: (steps taken, largest |residual|, code)."""
        if not done:
            return 0, largest, code
        sim.state = tuple(self.y.tolist())
        sim.steps, sim.energy_in_play = int(self.I[0]), float(self.F[6])
        if sound >= 0:
            sim._sound = sim.state if sound == sim.steps else tuple(self.S.tolist())
        return done, float(self.F[4]), code


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
        return step(self.y, h, K)

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


def kernel_for(dynamics, step, stepped_elsewhere=None):
    """The compiled kernel of a scene, or None (no numba, ARM_SIM_COMPILED=0, an adaptive
    step, or an effect whose stored energy has no compiled form); `stepped_elsewhere`
    (switches located, a driver checked step by step): its residual only."""
    if not compilable(dynamics, step) or energy_source(dynamics) is None:
        return None
    return Kernel(dynamics, step, stepped_elsewhere is None)


def smooth(books) -> bool:
    """Books kernels.run_books takes on a smooth scene: the error books at the planned count,
    or none at all (estimate off, a count the stability plan takes)."""
    if isinstance(books, Off):
        return books.stepper is None and books.substeps <= MAX_SUBSTEPS
    return isinstance(books, accuracy.Accuracy) and books.stepper is None and \
        books.free.n == books.substeps
