"""The compiled path (extra `fast`: numba): the scene's generated code, compiled.

The right-hand side (dynamics.py) and the step (integrators.py) are plain Python text. Here
they are written once more into a module file named by the hash of that text, with three
changes: the command the policies read becomes an argument K (a float array: the command,
then, for Batch, the constants that vary per arm), f(...) becomes rhs(..., K), and every
function is numba.njit(cache=True). A loop around them (kernels.run_books) takes what
Simulator.run takes step by step on a smooth scene: the planned sub-steps, the error
books' shadow and checks, the divergence checks and the largest |energy balance residual|,
handing back to Python each step where something is to be said; another advances every arm
of a Batch, arms in parallel. A switching scene's modes (events.py) each get their rhs
compiled with the step when first met, with the mode's switching functions and a run of
its steps in which nothing can switch (switch_kernel.py, switch_run.py).

The same operations in the same order, on IEEE doubles without fast-math, with cos, sin
and exp from the same libm: the states are the pure-Python path's bit for bit
(test_compiled.py). numba caches the machine code next to the module file
(ARM_SIM_CACHE, default ~/.cache/arm_sim_ros): a scene compiles once per machine.
Without numba (or with ARM_SIM_COMPILED=0) nothing here is used.
"""
from __future__ import annotations

import hashlib
import importlib.util
import inspect
import os
import re
import sys
from pathlib import Path

from ..trust import accuracy, controller, guard, shadow
from ..stepping import integrators
from ..trust.controller import SAFETY
from .kernels import KERNELS
from .switch_kernel import SWITCH_KERNEL, driver_source, template_items
from ..model import MAX_ANGLE

try:                      # the optional extra: pip install -e '.[fast]'
    import numba
except ImportError:       # pragma: no cover - exercised where numba is absent
    numba = None

# Energy each effect stores (effects' stored_energy, the same operations in the same order:
# squares as products, since Python's x ** 2 is libm's pow, 1 ulp off numba's x * x in about
# 1 value in 1000); an effect that stores energy and is not here keeps its scene on Python's path.
STORED = {
    "gravity": lambda e, arm: (["gravity", "k1", "k2"], "{0} * ({1} * sin(q1) + {2} * sin(q1 + q2))",
                               [e.gravity, *arm.gravity_coefficients]),
    "springs": lambda e, arm: ([], "0.5 * ({0} * (q1 - {1}) * (q1 - {1}) + {2} * (q2 - {3})"
                               " * (q2 - {3}))",
                               [e.spring_constants[0], e.rest_positions[0],
                                e.spring_constants[1], e.rest_positions[1]]),
    "motors": lambda e, arm: ([], "0.5 * ({0} * x0 * x0 + {1} * x1 * x1)" if e.windings
                              else "0.0", list(e.inductance) if e.windings else []),
}


def _limit_energy(e, arm):
    """CompliantLimits.stored_energy, term by term (a hard limit stores none)."""
    if e.hard:
        return [], "0.0", []
    total, values = "0.0", [e.spring]
    for j, (lo, hi) in enumerate(zip(e.lower, e.upper)):
        over, under = f"(q{j + 1} - {{{len(values)}}})", f"(q{j + 1} - {{{len(values) + 1}}})"
        values += [hi, lo]
        total = (f"({total} + 0.5 * ({over} + abs({over})) * 0.5 * ({over} + abs({over}))"
                 f" + 0.5 * ({under} - abs({under})) * 0.5 * ({under} - abs({under})))")
    return [], "0.5 * {0} * " + total, values


STORED["joint_limits"] = _limit_energy
# What run_books writes in from the books' modules (kernels.py): the same numbers.
BOOKS_CONSTANTS = {**{n: getattr(controller, n) for n in ("KI", "KP", "KEEP", "SAFETY",
                                                          "MAX_GROWTH", "MAX_SHRINK")},
                   **{n: getattr(shadow, n) for n in ("ROUGH", "SMOOTH", "FIRST_EVERY",
                                                      "MIN_EVERY", "MAX_EVERY", "LOST",
                                                      "ROUNDING")},
                   **{n: getattr(guard, n) for n in ("CHECK_EVERY", "FLOOR", "BOOKS_FRACTION")},
                   "GIVE_UP": accuracy.GIVE_UP, "NO_GAIN": accuracy.NO_GAIN,
                   "MAX_ANGLE": MAX_ANGLE}
STORELESS = ("actuator", "effort_limits", "damping", "payload", "controller_model", "friction")


def available() -> bool:
    """numba imports, ARM_SIM_COMPILED is not 0 and the cache directory is writable."""
    if numba is None or os.environ.get("ARM_SIM_COMPILED", "1") == "0":
        return False
    try:
        cache_dir().mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return os.access(cache_dir(), os.W_OK)


def cache_dir() -> Path:
    return Path(os.environ.get("ARM_SIM_CACHE") or Path.home() / ".cache" / "arm_sim_ros")


def _signature(width: int) -> str:
    return ", ".join(f"s{k}" for k in range(width))


def _reads(names) -> list[str]:
    """The lines that read the constants `names` from K (after the command: K[0], K[1])."""
    return [f"    {name} = K[{2 + j}]" for j, name in enumerate(names)]


def rhs_source(source: str, names) -> str:
    """The generated rhs with the command and the constants `names` read from K."""
    lines = source.replace("command[0]", "K[0]").replace("command[1]", "K[1]")
    lines = lines.replace("MIN(", "min(").replace("MAX(", "max(").splitlines()
    return "\n".join([lines[0].replace("):", ", K):"), *_reads(names), *lines[1:]]) + "\n"


def step_source(step, names) -> str:
    """The generated step with f(...) the module's rhs(..., K), its constants from K."""
    source = step.source.replace("def step(f, y, h):", "def step(y, h, K):\n"
                                 + "\n".join(_reads(names)))
    return re.sub(r"= f\(([^)]*)\)", r"= rhs(\1, K)", source)


def energy_source(dynamics):
    """(source, values): energy(y, K), residual(y, K, E0, R0, R1) and inputs(y, R0) as
    Simulator.energy, .residual and the sum of its input channels compute them (njit),
    their constants read from K[2:] in the order of `values`; None where an effect's
    stored energy has no compiled form."""
    arm, terms = dynamics.arm, []
    values = list(arm.mass_constants)
    for effect in dynamics.active:
        if effect.name in STORED:
            _, text, numbers = STORED[effect.name](effect, arm)
            terms.append(text.format(*(f"EC{len(values) + n}" for n in range(len(numbers)))))
            values += numbers
        elif effect.name not in STORELESS:
            return None
    width = 4 + len(dynamics.extra) + len(dynamics.channels)
    first = 4 + len(dynamics.extra)
    inputs = "".join(f" + s{first + i}" for i, k in enumerate(dynamics.channel_kinds)
                     if k == "input")
    losses = "".join(f" + s{first + i}" for i, k in enumerate(dynamics.channel_kinds)
                     if k == "loss")
    extra = "".join(f"    x{k} = s{4 + k}\n" for k in range(len(dynamics.extra)))
    reads = "".join(f"    EC{n} = K[{2 + n}]\n" for n in range(len(values)))
    stored = "0.0" + "".join(f" + {t}" for t in terms)
    body = (f"    {_signature(width)}, = y\n{reads}    q1, q2, u1, u2 = s0, s1, s2, s3\n{extra}"
            f"    c2 = cos(q2)\n    m11 = EC0 + 2.0 * EC1 * c2\n    m12 = EC2 + EC1 * c2\n"
            f"    kinetic = 0.5 * (m11 * u1 * u1 + 2.0 * m12 * u1 * u2 + EC3 * u2 * u2)\n"
            f"    stored = {stored}\n")
    return (f"@njit(cache=True)\ndef energy(y, K):\n{body}    return 0.0 + kinetic + stored\n\n"
            f"@njit(cache=True)\ndef residual(y, K, E0, R0, R1):\n{body}"
            f"    work = R0{inputs}\n    lost = R1{losses}\n"
            f"    return 0.0 + kinetic + stored - E0 - work + lost\n\n"
            f"@njit(cache=True)\ndef inputs(y, R0):\n    {_signature(width)}, = y\n"
            f"    return R0{inputs}\n"), values


NO_ENERGY = ("@njit(cache=True)\ndef energy(y, K):\n    return 0.0\n\n"
             "@njit(cache=True)\ndef residual(y, K, E0, R0, R1):\n    return 0.0\n\n"
             "@njit(cache=True)\ndef inputs(y, R0):\n    return R0\n")


def functions_source(text: str, names) -> str:
    """Generated functions beside a mode's rhs (its probe and guard, the drivers' check),
    njit, their constants read from K as the rhs reads them."""
    out = []
    for block in re.split(r"(?m)^(?=def )", text):
        if block.strip():
            out += ["@njit(cache=True)", rhs_source(block, names)]
    return re.sub(r"probe\(([^)]*)\)\[2:\]", r"probe(\1, K)[2:]", "\n".join(out))


def module_source(dynamics, step, rhs=None, guards=""):
    """(source, constant names): the module of rhs (the scene's, or a mode's `rhs` source),
    step, residual and the kernels, all njit; with a mode's `guards` (its probe and guard
    source), its switching run too (switch_kernel.py). Constants are read from K
    (constants_of), not written in: the source, and so the compiled code, depends on the
    scene's structure only, not on its parameter values (a parameter sweep compiles once)."""
    rhs = dynamics.source if rhs is None else rhs
    values = {**dynamics.function.__globals__, **getattr(step, "constants", {})}
    guards = guards and guards + driver_source(dynamics)
    found = set(re.findall(r"\b[A-Z][A-Z0-9_]*\b", rhs + step.source + guards))
    names = sorted(n for n in found if n in values and isinstance(values[n], (int, float))
                   and not isinstance(values[n], bool))
    lines = ["from math import ceil, cos, exp, isfinite, sin", "from numba import njit, prange", ""]
    if "COEFFICIENTS" in step.source:    # the exponential step's coefficients, compiled too
        lines += [f"PHI_SERIES = {integrators.PHI_SERIES!r}",
                  "@njit(cache=True)\n" + inspect.getsource(integrators.phi),
                  "@njit(cache=True)\n" + inspect.getsource(integrators.exponential_rk4),
                  "COEFFICIENTS = exponential_rk4"]
    width = 4 + len(dynamics.extra) + len(dynamics.channels)
    energy = energy_source(dynamics)
    for function in (rhs_source(rhs, names), step_source(step, names)):
        lines += ["@njit(cache=True)", function]
    lines.append(energy[0] if energy else NO_ENERGY)
    fill = dict(items=", ".join(f"y[{k}]" for k in range(width)),
                zitems=", ".join(f"z[{k}]" for k in range(width)),
                ditems=", ".join(f"state[{k}] - D[{k}] if {k} < states else state[{k}]"
                                 for k in range(width)),
                columns=", ".join(f"Y[{k}, a]" for k in range(width)),
                width=width, **BOOKS_CONSTANTS)
    lines.append(KERNELS.format(**fill))
    if guards:
        lines += [functions_source(guards, names),
                  SWITCH_KERNEL.format(**fill, **template_items(4 + len(dynamics.extra)))]
    return "\n".join(lines) + "\n", names


def constants_of(names, values, command=(0.0, 0.0)):
    """K: the command, then the constants `names` (floats; Batch: per-arm arrays too)."""
    import numpy as np
    return np.array([command[0], command[1], *(values[n] for n in names)], dtype=float)


def load(source: str):
    """The module of `source`, written once to the cache directory under its hash."""
    digest = hashlib.sha256(source.encode()).hexdigest()[:20]
    name = f"arm_sim_kernel_{digest}"
    if name in sys.modules:
        return sys.modules[name]
    directory = cache_dir()
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{name}.py"
    if not path.is_file() or path.read_text() != source:
        temporary = path.with_suffix(f".{os.getpid()}.tmp")
        temporary.write_text(source)
        os.replace(temporary, path)        # atomic: two processes may write it at once
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


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
        self.I, self.F = np.zeros(18, dtype=np.int64), np.zeros(15)
        self.command, self.lowest = dynamics.command, None
        self.switched = None      # a switching scene's runs in one mode (switch_run.py)

    def run(self, sim, left: int, largest: float):
        """(steps taken, largest |residual|) of Simulator.run without a callback: steps in
        one compiled call while nothing is to be said; the step Python must take (a switch,
        a driver, a new highest count, a fault ...) as Simulator.step, its residual
        compiled."""
        books, done, code = sim.accuracy, 0, 1
        if self.plain and not sim.diverged and isinstance(books, accuracy.Accuracy) and \
                books.stepper is None and books.free.n == books.substeps:
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
        shadow, I, F, n, h = books.shadow, self.I, self.F, books.states, sim.step_size
        run, K = run or self.module.run_books, self.K if K is None else K
        K[0], K[1] = self.command
        self.y[:] = sim.state
        known = shadow.local is not None
        followed = known and not shadow.lost and sim.state is shadow.last
        if known:
            self.L[:n] = shadow.local
        if followed:
            self.z[:] = shadow.shadow
        self.O[:n] = shadow.offset or [0.0] * n
        if self.lowest is None:
            self.lowest = guard.lowest_energy(sim)
        I[:] = (sim.steps, books.due, books.since, books.booked_taken, books.substeps,
                books.every, books.free.floor, books.free.cap, books.cap, books.most,
                books.capped, n, books.order, known, followed, shadow.lost,
                books.said_lost or books.emit is None, sim.books_fault is not None)
        F[:] = (h, sim.initial_energy, *sim.retired, largest, shadow.largest,
                sim.energy_in_play, books.error_estimate, books.free.previous, books.tolerance,
                SAFETY * books.target(h), books.target(h), books.factor, self.lowest,
                float(books.order))
        done, code, sound = run(self.y, self.z, self.L, self.O, self.G, self.S, I, F, K,
                                self.C, left, *more)
        if not done:
            return 0, largest, code
        sim.state = tuple(self.y.tolist())
        sim.steps, books.due, books.since, books.booked_taken = (int(v) for v in I[:4])
        if int(I[4]) != books.substeps:
            books.use(int(I[4]))
        books.every = int(I[5])
        books.error_estimate, books.free.previous = float(F[7]), float(F[8])
        if I[13]:
            shadow.local = self.L[:n].tolist()
        if I[14]:
            shadow.shadow, shadow.offset = tuple(self.z.tolist()), self.O[:n].tolist()
            shadow.last = sim.state
        shadow.largest, shadow.lost = float(F[5]), bool(I[15])
        sim.energy_in_play = float(F[6])
        if sound >= 0:
            sim._sound = sim.state if sound == sim.steps else tuple(self.S.tolist())
        return done, float(F[4]), code


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


def compilable(dynamics, step) -> bool:
    """numba on, a fixed step, no servo, and every constant the rhs reads a number (MIN and
    MAX, the clamps' functions, become min and max). A servo's set-points are a list the node
    changes: Python's path, on every interface (an effort joint reads none), so that a switch
    of interface while the node runs never meets a first compile (seconds without a tick)."""
    values = dynamics.function.__globals__
    names = set(re.findall(r"\b[A-Z][A-Z0-9_]*\b", dynamics.source)) - {"MIN", "MAX"}
    return (available() and hasattr(step, "source") and not hasattr(step, "rtol")
            and not any(effect.name == "servo" for effect in dynamics.active)
            and all(isinstance(values.get(n, 0.0), (int, float)) for n in names))


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
