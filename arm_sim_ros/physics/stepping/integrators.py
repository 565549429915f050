"""Explicit Runge-Kutta methods as data (Butcher tableaux) and the one routine that steps them.

`compile_step` turns a tableau into straight-line Python for the arm's state
(q1, q2, qd1, qd2, *accounting channels), as scipy.integrate does with its tableaux but
unrolled: the coefficients are data, the loop over stages happens once, at compile time.
The accounting channels (actuator work, dissipated energy) are integrated with the same
weights from the same stages as the mechanical state.

Two small generalisations cover every method offered here:
- partitioned tableaux: positions may combine the stage velocities with their own
  weights (position_a, position_b) while velocities and channels use (a, b). A stage
  whose slopes no weight uses is never evaluated. Semi-implicit Euler is then data:
  velocity first from the old state, position from the new velocity, one evaluation.
- embedded pairs: a second weight row (embedded_b) estimates the local error; the
  compiled step advances by exactly h through error-controlled sub-steps, so an adaptive
  method still lands on every publish time and keeps the step(f, y, h) signature.
"""
from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from math import lcm, nan

from .generated import source_code

F = Fraction


@dataclass(frozen=True)
class ButcherTableau:
    name: str
    c: tuple
    a: tuple          # strictly lower-triangular rows, a[i] has i entries
    b: tuple
    order: int
    position_a: tuple | None = None   # partitioned methods: weights of the stage velocities
    position_b: tuple | None = None   # in the positions; None = the same as a and b
    embedded_b: tuple | None = None   # embedded pair: the lower-order solution's weights
    embedded_order: int = 0
    description: str = ""

    def __post_init__(self):
        stages = len(self.b)
        if len(self.c) != stages or len(self.a) != stages:
            raise ValueError(f"{self.name}: c, a and b must have one entry per stage")
        for rows, weights, part in ((self.a, self.b, "a"), (self.pos_a, self.pos_b, "position_a"),
                                    (self.a, self.embedded_b or self.b, "a")):
            if len(rows) != stages or len(weights) != stages:
                raise ValueError(f"{self.name}: {part} and its weights need one entry per stage")
            for i, row in enumerate(rows):
                if len(row) != i:
                    raise ValueError(f"{self.name}: row {i} of {part} must have {i} entries "
                                     "(explicit method)")
                if sum(row) != self.c[i]:
                    raise ValueError(f"{self.name}: row {i} of {part} must sum to c[{i}]")
            if sum(weights) != 1:
                raise ValueError(f"{self.name}: weights must sum to 1")

    @property
    def stages(self) -> int:
        return len(self.b)

    @property
    def pos_a(self) -> tuple:
        return self.a if self.position_a is None else self.position_a

    @property
    def pos_b(self) -> tuple:
        return self.b if self.position_b is None else self.position_b

    @property
    def adaptive(self) -> bool:
        return self.embedded_b is not None

    def evaluated_stages(self) -> list[int]:
        """Stages whose accelerations some weight uses; only these call f."""
        return [i for i in range(self.stages)
                if self.b[i] != 0 or (self.embedded_b and self.embedded_b[i] != 0)
                or any(row[i] != 0 for row in self.a[i + 1:])]


EULER = ButcherTableau("euler", c=(F(0),), a=((),), b=(F(1),), order=1,
                       description="explicit Euler")
SEMI_IMPLICIT_EULER = ButcherTableau(
    # Velocity from the old state's acceleration, then position from the new velocity
    # (MuJoCo's "Euler"). Stage 1 is never evaluated: only its velocity is used.
    "semi_implicit_euler",
    c=(F(0), F(1)), a=((), (F(1),)), b=(F(1), F(0)), order=1,
    position_a=((), (F(1),)), position_b=(F(0), F(1)),
    description="semi-implicit (symplectic) Euler")
MIDPOINT = ButcherTableau("midpoint", c=(F(0), F(1, 2)), a=((), (F(1, 2),)), b=(F(0), F(1)),
                          order=2, description="explicit midpoint")
RK4 = ButcherTableau(
    "rk4",
    c=(F(0), F(1, 2), F(1, 2), F(1)),
    a=((), (F(1, 2),), (F(0), F(1, 2)), (F(0), F(0), F(1))),
    b=(F(1, 6), F(1, 3), F(1, 3), F(1, 6)),
    order=4,
    description="classical Runge-Kutta",
)
RK38 = ButcherTableau(
    "rk38",
    c=(F(0), F(1, 3), F(2, 3), F(1)),
    a=((), (F(1, 3),), (F(-1, 3), F(1)), (F(1), F(-1), F(1))),
    b=(F(1, 8), F(3, 8), F(3, 8), F(1, 8)),
    order=4,
    description="Kutta's 3/8 rule",
)
DOPRI5 = ButcherTableau(
    # Dormand & Prince (1980); the 7th stage is the next step's first (FSAL).
    "dopri5",
    c=(F(0), F(1, 5), F(3, 10), F(4, 5), F(8, 9), F(1), F(1)),
    a=((),
       (F(1, 5),),
       (F(3, 40), F(9, 40)),
       (F(44, 45), F(-56, 15), F(32, 9)),
       (F(19372, 6561), F(-25360, 2187), F(64448, 6561), F(-212, 729)),
       (F(9017, 3168), F(-355, 33), F(46732, 5247), F(49, 176), F(-5103, 18656)),
       (F(35, 384), F(0), F(500, 1113), F(125, 192), F(-2187, 6784), F(11, 84))),
    b=(F(35, 384), F(0), F(500, 1113), F(125, 192), F(-2187, 6784), F(11, 84), F(0)),
    order=5,
    embedded_b=(F(5179, 57600), F(0), F(7571, 16695), F(393, 640), F(-92097, 339200),
                F(187, 2100), F(1, 40)),
    embedded_order=4,
    description="Dormand-Prince 5(4), error-controlled",
)

# RK4's tableau; its step integrates the winding currents' decay -R/L exactly (exponential
# RK4, below): with windings L/R << h it needs no sub-steps for them. Without extra states
# it is RK4, bit for bit.
EXPONENTIAL_RK4 = ButcherTableau(
    "exponential_rk4", c=RK4.c, a=RK4.a, b=RK4.b, order=4,
    description="classical Runge-Kutta; winding currents by exponential RK4 (Krogstad)")

INTEGRATORS = {t.name: t for t in (RK4, EULER, SEMI_IMPLICIT_EULER, MIDPOINT, RK38, DOPRI5,
                                   EXPONENTIAL_RK4)}

MECHANICAL = ("q1", "q2", "u1", "u2")
STAGE_INPUTS = ("p1", "p2", "v1", "v2")

# Embedded-pair defaults: tighter than RK4 at h = 0.01 on the release (about 1e-6).
DEFAULT_RTOL = 1e-8
DEFAULT_ATOL = 1e-10


def combination(base: str | None, coefficients, terms) -> str:
    """`base + h * (n1*k1 + n2*k2 ...) / den` with exact integer numerators."""
    pairs = [(F(c), k) for c, k in zip(coefficients, terms) if c != 0]
    if not pairs:
        return base or "0.0"
    den = lcm(*(c.denominator for c, _ in pairs))
    parts = []
    for c, k in pairs:
        n = c.numerator * (den // c.denominator)
        parts.append(k if n == 1 else f"{n}.0 * {k}")
    total = " + ".join(parts).replace("+ -", "- ")
    total = f"({total})" if len(parts) > 1 else total
    head = "h * " if base is None else f"{base} + h * "
    return head + total + (f" / {den}.0" if den != 1 else "")


def state_names(extra: int, channels: int) -> tuple:
    """State entry names: angles, velocities, an effect's extra states, channels."""
    return (MECHANICAL + tuple(f"x{k}" for k in range(extra))
            + tuple(f"w{j}" for j in range(channels)))


def slope_names(extra: int, channels: int) -> list:
    return (["v1", "v2", "a1", "a2"] + [f"xd{k}" for k in range(extra)]
            + [f"r{j}" for j in range(channels)])


def stage_lines(tableau: ButcherTableau, channels: int, first_given: bool,
                 extra: int = 0) -> list[str]:
    """Stage inputs and f calls, skipping whatever no weight uses."""
    evaluated = tableau.evaluated_stages()
    lines = []
    for i in range(tableau.stages):
        velocity_used = (i in evaluated or tableau.pos_b[i] != 0
                         or any(row[i] != 0 for row in tableau.pos_a[i + 1:]))
        names, inputs = [], []
        for n, (x, stage, slope) in enumerate(zip(MECHANICAL, STAGE_INPUTS, ("v1", "v2", "a1", "a2"))):
            is_position = n < 2
            if not (i in evaluated if is_position else velocity_used):
                continue
            rows = tableau.pos_a if is_position else tableau.a
            names.append(f"{stage}_{i}")
            inputs.append(combination(x, rows[i], [f"{slope}_{j}" for j in range(i)]))
        if i in evaluated:   # extra states (winding currents...) are read only where f is
            for k in range(extra):
                names.append(f"e{k}_{i}")
                inputs.append(combination(f"x{k}", tableau.a[i], [f"xd{k}_{j}" for j in range(i)]))
        if names:
            lines.append(f"    {', '.join(names)} = {', '.join(inputs)}")
        if i in evaluated and not (first_given and i == 0):
            outputs = ([f"a1_{i}", f"a2_{i}"] + [f"xd{k}_{i}" for k in range(extra)]
                       + [f"r{j}_{i}" for j in range(channels)])
            arguments = [f"p1_{i}", f"p2_{i}", f"v1_{i}", f"v2_{i}"] + [f"e{k}_{i}" for k in range(extra)]
            lines.append(f"    {', '.join(outputs)}, = f({', '.join(arguments)})")
    return lines


def final_terms(tableau: ButcherTableau, channels: int, position_b, b, extra: int = 0) -> list[str]:
    """The weighted sums of the slopes for each state entry (base None: the increment only)."""
    return [(position_b if n < 2 else b, x, [f"{k}_{j}" for j in range(tableau.stages)])
            for n, (x, k) in enumerate(zip(state_names(extra, channels), slope_names(extra, channels)))]


def exec_source(source: str, name: str, namespace: dict):
    exec(source_code(source, name), namespace)
    return namespace


def compile_step(tableau: ButcherTableau, channels: int = 0, rtol: float = DEFAULT_RTOL,
                 atol: float = DEFAULT_ATOL, extra: int = 0):
    """step(f, y, h) -> next y, for y = (q1, q2, qd1, qd2, *extra, *channels) and
    f(q1, q2, qd1, qd2, *extra) -> (qdd1, qdd2, *extra rates, *channel rates). `extra` are
    states effects add (winding currents), integrated like velocities. rtol/atol only
    matter for embedded pairs."""
    if tableau.adaptive:
        return _compile_adaptive(tableau, channels, rtol, atol, extra)
    state = state_names(extra, channels)
    lines = ["def step(f, y, h):", f"    {', '.join(state)}, = y"]
    lines += stage_lines(tableau, channels, first_given=False, extra=extra)
    final = [combination(x, w, terms)
             for w, x, terms in final_terms(tableau, channels, tableau.pos_b, tableau.b, extra)]
    lines.append(f"    return ({', '.join(final)},)")
    source = "\n".join(lines) + "\n"
    step = exec_source(source, f"<{tableau.name} step, {extra} extra, {channels} channels>",
                       {})["step"]
    step.source = source
    return step


# Step-size controller (Hairer, Norsett & Wanner, II.4): safety factor and growth limits.
SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0


def _compile_adaptive(tableau: ButcherTableau, channels: int, rtol: float, atol: float,
                      extra: int = 0):
    """One attempt is straight-line code: new state, last-stage slopes (FSAL) and the
    RMS error norm scaled by atol + rtol |y|; the controller around it is a plain loop."""
    if not (rtol > 0 and atol > 0):
        raise ValueError(f"{tableau.name}: rtol and atol must be positive, got {rtol}, {atol}")
    state = state_names(extra, channels)
    first = [f"{k}_0" for k in slope_names(extra, channels)[2:]]
    last = tableau.stages - 1
    lines = [f"def attempt(f, {', '.join(state)}, h, {', '.join(first)}):"]
    lines += stage_lines(tableau, channels, first_given=True, extra=extra)
    error_weights = [b - e for b, e in zip(tableau.b, tableau.embedded_b)]
    squares = []
    for (w, x, terms), (ew, _, _) in zip(final_terms(tableau, channels, tableau.pos_b, tableau.b, extra),
                                         final_terms(tableau, channels, error_weights, error_weights,
                                                extra)):
        lines.append(f"    n_{x} = {combination(x, w, terms)}")
        lines.append(f"    d_{x} = {combination(None, ew, terms)}")
        lines.append(f"    e_{x} = d_{x} / (ATOL + RTOL * max(abs({x}), abs(n_{x})))")
        squares.append(f"e_{x} * e_{x}")
    outputs = [f"{k}_{last}" for k in slope_names(extra, channels)[2:]]
    lines.append(f"    return ({', '.join(f'n_{x}' for x in state)},), "
                 f"({', '.join(outputs)},), sqrt(({' + '.join(squares)}) / {len(state)}.0), "
                 f"max({', '.join(f'abs(d_{x})' for x in state[:4 + extra])})")
    source = "\n".join(lines) + "\n"
    namespace = exec_source(source, f"<{tableau.name} attempt, {channels} channels>",
                      {"RTOL": float(rtol), "ATOL": float(atol), "sqrt": __import__("math").sqrt})
    attempt = namespace["attempt"]
    exponent = -1.0 / (min(tableau.order, tableau.embedded_order) + 1)
    size = len(state)

    def step(f, y, h):
        # Stateless between calls (each publish interval starts from a trial sub-step of
        # h), so reset() and replays are reproducible bit for bit.
        slopes = f(*y[:4 + extra])
        done, dt, step.last_error = 0.0, h, 0.0
        step.last_sizes = sizes = []          # the accepted sub-steps (trust/embedded.py)
        while True:
            remaining = h - done
            final = dt >= 0.99 * remaining       # no sliver sub-step before the boundary
            if final:
                dt = remaining
            new, new_slopes, error, local = attempt(f, *y, dt, *slopes)
            if error <= 1.0:
                step.last_error += local      # the pair's estimate, rad and rad/s
                sizes.append(dt)
                if final:
                    return new
                y, slopes, done = new, new_slopes, done + dt
                factor = MAX_FACTOR if error == 0.0 else min(MAX_FACTOR, SAFETY * error ** exponent)
            else:                                 # also NaN / inf: shrink, never accept
                factor = max(MIN_FACTOR, SAFETY * error ** exponent) if error < float("inf") else MIN_FACTOR
            dt *= factor
            if not dt > 1e-12 * h:
                return (nan,) * size              # cannot meet the tolerance: say so, non-finite

    step.source = source
    step.rtol, step.atol, step.last_error, step.last_sizes = float(rtol), float(atol), 0.0, []
    step.channels = channels
    return step


def integrates_decay_exactly(tableau: ButcherTableau) -> bool:
    """Whether the step of `tableau` integrates the extra states' linear decays exactly
    (the exponential RK4, exponential.py); other methods step them like the rest (and
    sub-step for them)."""
    return tableau is EXPONENTIAL_RK4
