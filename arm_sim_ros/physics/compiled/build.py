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
(ARM_SIM_CACHE, default ~/.cache/arm_sim_ros): a scene compiles once per machine, shared by
every checkout and venv (cache.py).
Without numba (or with ARM_SIM_COMPILED=0) nothing here is used.
"""
from __future__ import annotations

import hashlib
import importlib.util
import inspect
import os
import re
import sys
from functools import lru_cache
from pathlib import Path

from ..trust import accuracy, controller, guard, shadow
from . import apart, cache
from .entries import check_entries, say_once, set_aside
from ..stepping import exponential
from .kernels import BATCH, BOOKS_PARTS, HELPERS, KERNELS, run_loop
from . import draws, sensed as sensing
from .batched import run_many
from .switch_kernel import SWITCH_KERNEL, driver_source, template_items
from ..model import MAX_ANGLE
from ..dynamics import stage_terms

try:              # in the default install where numba has a wheel (scripts/venv.bash)
    import numba
except Exception as error:   # absent, or installed and broken (an llvmlite without its library)
    numba, MISSING = None, f"{type(error).__name__}: {error}"
if numba is not None:     # a first compile says so, and is timed (cache.py)
    from numba.core import event as numba_event
    cache.watch(numba_event)

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
                   "THREE_LEVELS": accuracy.THREE_LEVELS,
                   "MAX_ANGLE": MAX_ANGLE}
STORELESS = ("actuator", "effort_limits", "damping", "payload", "controller_model", "friction",
             "servo")


def available() -> bool:
    """numba imports, ARM_SIM_COMPILED is not 0, the cache a writable directory: else the
    pure-Python path, one line saying why (but for ARM_SIM_COMPILED=0, which chose it)."""
    if os.environ.get("ARM_SIM_COMPILED", "1") == "0":
        return False
    if numba is None:
        say_once(f"arm_sim_ros: numba does not import ({MISSING}): the pure-Python path, "
                 "slower with the same numbers; `pip install numba==0.68.1` gives the "
                 "compiled path (ARM_SIM_COMPILED=0 chooses pure Python without this line)")
        return False
    problem = unusable(cache_dir())
    if problem:
        say_once(f"arm_sim_ros: the kernel cache {cache_dir()} {problem}: the pure-Python "
                 "path, slower with the same numbers; set ARM_SIM_CACHE to a writable "
                 "directory (ARM_SIM_COMPILED=0 chooses pure Python without this line)")
    return not problem


@lru_cache(maxsize=None)
def unusable(directory: Path) -> str | None:
    """Why the kernel cache `directory` cannot be used (a file there, no write permission),
    None if it can: made if missing, and written to once, as numba will write to it (once
    a process: every simulator asks)."""
    if directory.exists() and not directory.is_dir():
        return "is a file, not a directory"
    try:
        directory.mkdir(parents=True, exist_ok=True)
        probe = directory / f".probe.{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as error:
        return f"is not a writable directory ({error.strerror or error})"
    return None


def cache_dir() -> Path:
    return Path(os.environ.get("ARM_SIM_CACHE") or Path.home() / ".cache" / "arm_sim_ros")


@lru_cache(maxsize=1024)
def capitals(text: str) -> frozenset:
    """The names in capitals a generated text reads (its constants), once per text."""
    return frozenset(re.findall(r"\b[A-Z][A-Z0-9_]*\b", text))


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


def step_source(text: str, names) -> str:
    """The generated step with f(...) the module's rhs(..., K), its constants from K; and
    step_from(y, h, K, first), the same step with its first stage's slopes given (the rhs
    at y: a check's step and its first half share them, the same numbers computed once)."""
    source = text.replace("def step(f, y, h):", "def step(y, h, K):\n"
                                 + "\n".join(_reads(names)))
    source = source.replace("f.response(q1, q2)", "response(q1, q2, K)")   # (exponential.py)
    given = re.sub(r"= f\(([^)]*)\)", "= first", source.replace(
        "def step(y, h, K):", "def step_from(y, h, K, first):"), count=1)
    return "\n@njit(cache=True)\n".join(
        re.sub(r"= f\(([^)]*)\)", r"= rhs(\1, K)", text) for text in (source, given))


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


SET_POINTS = {f"SP{k}": 0.0 for k in range(6)}   # a continuous servo's, read from K


def set_points(source: str) -> str:
    """A continuous servo's set-points SP[k] (a list the node changes) as constants SPk,
    which the kernel writes into K before each call (runs.Kernel.given)."""
    return re.sub(r"\bSP\[(\d)\]", r"SP\1", source)


def torque_source(dynamics) -> str:
    """torque(q1, q2, u1, u2, *extra): the torque the joints receive (Simulator.joint_torque,
    the same lines: the mode-free stage terms), for recorded(T, row, state, K), which writes
    a trajectory's row (q1, q2, q̇1, q̇2, τ1, τ2)."""
    names = ", ".join(["q1", "q2", "u1", "u2", *dynamics.extra])
    drives = any(effect.drives for effect in dynamics.active)
    return "\n".join([f"def torque({names}):", *(stage_terms(dynamics.active) + [
        "    return t1, t2"] if drives else ["    return 0.0, 0.0"])]) + "\n"


RECORDED = """
@njit(cache=True)
def recorded(T, row, state, K):
    t1, t2 = torque({slopes}, K)
    T[row, 0], T[row, 1], T[row, 2], T[row, 3] = state[0], state[1], state[2], state[3]
    T[row, 4], T[row, 5] = t1, t2
"""


def module_source(dynamics, step, rhs=None, guards="", sensed=False, energy=None):
    """(source, constant names): the module of rhs (the scene's, or a mode's `rhs` source),
    step, residual and the kernels, all njit; with a mode's `guards` (its probe and guard
    source), its switching run too (switch_kernel.py). Constants are read from K
    (constants_of), not written in: the source, and so the compiled code, depends on the
    scene's structure only, not on its parameter values (a parameter sweep compiles once).
    `sensed`: run_books takes the sensors' samples and the control loop's (sensed.py);
    `energy`: energy_source's, where the caller has it."""
    rhs = set_points(dynamics.source if rhs is None else rhs)
    values = {**dynamics.function.__globals__, **getattr(step, "constants", {}), **SET_POINTS}
    guards = guards and guards + driver_source(dynamics)
    torque = set_points(torque_source(dynamics))
    found = capitals(rhs) | capitals(step.source) | capitals(guards) | capitals(torque)
    names = sorted(n for n in found if n in values and isinstance(values[n], (int, float))
                   and not isinstance(values[n], bool))
    energy = energy_source(dynamics) if energy is None else energy
    return module_text(rhs, step.source, guards, torque, tuple(names),
                       energy[0] if energy else NO_ENERGY, tuple(dynamics.extra),
                       len(dynamics.channels), sensed), names


@lru_cache(maxsize=256)
def module_text(rhs: str, step_text: str, guards: str, torque: str, names: tuple, energy: str,
                extra: tuple, channels: int, sensed: bool) -> str:
    """The module's text from what module_source found: written once per structure in a
    process (a sweep builds a simulator per sample)."""
    lines = ["from math import ceil, cos, exp, inf, isfinite, log1p, sin",
             "import numpy as np", "from numba import njit, prange", ""]
    if "COEFFICIENTS" in step_text:    # the exponential step's coefficients, compiled too
        lines += [f"PHI_SERIES = {exponential.PHI_SERIES!r}",
                  "@njit(cache=True)\n" + inspect.getsource(exponential.phi),
                  "@njit(cache=True)\n" + inspect.getsource(exponential.exponential_rk4),
                  "COEFFICIENTS = exponential_rk4"]
    width = 4 + len(extra) + channels
    # the rhs (and beside it, with windings, its response: dynamics.response_source)
    lines += [functions_source(rhs, names)]
    for function in (step_source(step_text, names), rhs_source(torque, names)):
        lines += ["@njit(cache=True)", function]
    lines.append(energy)
    fill = dict(items=", ".join(f"y[{k}]" for k in range(width)),
                slopes=", ".join(f"state[{k}]" for k in range(4 + len(extra))),
                zitems=", ".join(f"z[{k}]" for k in range(width)),
                ditems=", ".join(f"state[{k}] - D[{k}] if {k} < states else state[{k}]"
                                 for k in range(width)),
                columns=", ".join(f"Y[{k}, a]" for k in range(width)),
                width=width, **BOOKS_CONSTANTS)
    kernels = KERNELS if not sensed else HELPERS + run_loop(
        **(BOOKS_PARTS | sensing.parts(extra, width))) + BATCH
    if sensed:
        lines += [draws.source(), sensing.SENSING]
    lines.append(kernels.format(**fill) + RECORDED.format(**fill)
                 + run_many(sensing.MORE if sensed else ""))
    if guards:
        lines += [functions_source(guards, names),
                  SWITCH_KERNEL.format(**fill, **template_items(4 + len(extra)))]
    return "\n".join(lines) + "\n"


def constants_of(names, values, command=(0.0, 0.0)):
    """K: the command, then the constants `names` (floats; Batch: per-arm arrays too)."""
    import numpy as np
    return np.array([command[0], command[1], *(values[n] for n in names)], dtype=float)


@lru_cache(maxsize=256)
def module_name(source: str) -> str:
    """The cached module's name: the hash of its text, so a changed text is a new module."""
    return f"arm_sim_kernel_{hashlib.sha256(source.encode()).hexdigest()[:20]}"


def load(source: str):
    """The module of `source`, written once to the cache directory under its hash; a file
    there that is not that text (cut short, garbage) is set aside and written anew, and
    numba's files of its functions are read checked (entries.py)."""
    name = module_name(source)
    if name in sys.modules:
        return sys.modules[name]
    directory = cache_dir()
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{name}.py"
    text = source.encode()
    try:
        written = path.read_bytes()
    except FileNotFoundError:
        written = None
    except OSError as error:          # a directory in its place, unreadable
        written = error.strerror or str(error)
    if written != text:
        if written is not None:       # numba's files of it go stale with its new stamp
            set_aside(str(path), "not the text its name's hash names"
                      if isinstance(written, bytes) else written)
        temporary = path.with_suffix(f".{os.getpid()}.tmp")
        temporary.write_bytes(text)
        os.replace(temporary, path)        # atomic: two processes may write it at once
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    check_entries(module)              # a damaged entry set aside: compiled again
    apart.compile_apart(module)        # a first compile's memory goes with a child process
    return module


def compilable(dynamics, step, servo: bool = False) -> bool:
    """numba on, a fixed step, no servo, and every constant the rhs reads a number (MIN and
    MAX, the clamps' functions, become min and max). A servo's set-points are a list the node
    changes: Python's path, on every interface (an effort joint reads none), so that a switch
    of interface while the node runs never meets a first compile (seconds without a tick).
    A servo sampled by a control loop is the torque it acts with (its law is the loop's,
    sensed.py, the same on every interface): compiled. `servo`: a continuous servo too (its
    set-points read from K: rollouts, where no interface changes)."""
    values = dynamics.function.__globals__
    names = capitals(set_points(dynamics.source)) - {"MIN", "MAX"}
    return (available() and hasattr(step, "source") and not hasattr(step, "rtol")
            and not any(effect.name == "servo" and effect.acting is None
                        and not (servo and not effect.rate) for effect in dynamics.active)
            and all(isinstance(values.get(n, 0.0), (int, float)) for n in names))
