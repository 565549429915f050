"""Explicit Runge-Kutta methods as data (Butcher tableaux) and the one routine that steps them.

`compile_step` turns a tableau into straight-line Python for the arm's state
(q1, q2, qd1, qd2, *accounting channels), as scipy.integrate does with its tableaux but
unrolled: the coefficients are data, the loop over stages happens once, at compile time.
The accounting channels (actuator work, dissipated energy) are integrated with the same
weights from the same stages as the mechanical state.
"""
from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from math import lcm

F = Fraction


@dataclass(frozen=True)
class ButcherTableau:
    name: str
    c: tuple
    a: tuple          # strictly lower-triangular rows, a[i] has i entries
    b: tuple
    order: int

    def __post_init__(self):
        stages = len(self.b)
        if len(self.c) != stages or len(self.a) != stages:
            raise ValueError(f"{self.name}: c, a and b must have one entry per stage")
        for i, row in enumerate(self.a):
            if len(row) != i:
                raise ValueError(f"{self.name}: row {i} of a must have {i} entries (explicit method)")
            if sum(row) != self.c[i]:
                raise ValueError(f"{self.name}: row {i} of a must sum to c[{i}]")
        if sum(self.b) != 1:
            raise ValueError(f"{self.name}: weights b must sum to 1")

    @property
    def stages(self) -> int:
        return len(self.b)


RK4 = ButcherTableau(
    "rk4",
    c=(F(0), F(1, 2), F(1, 2), F(1)),
    a=((), (F(1, 2),), (F(0), F(1, 2)), (F(0), F(0), F(1))),
    b=(F(1, 6), F(1, 3), F(1, 3), F(1, 6)),
    order=4,
)

INTEGRATORS = {t.name: t for t in (RK4,)}

MECHANICAL = ("q1", "q2", "u1", "u2")


def _combination(base: str, coefficients, terms) -> str:
    """`base + h * (n1*k1 + n2*k2 ...) / den` with exact integer numerators."""
    pairs = [(F(c), k) for c, k in zip(coefficients, terms) if c != 0]
    if not pairs:
        return base
    den = lcm(*(c.denominator for c, _ in pairs))
    parts = []
    for c, k in pairs:
        n = c.numerator * (den // c.denominator)
        parts.append(k if n == 1 else f"{n}.0 * {k}")
    total = " + ".join(parts).replace("+ -", "- ")
    total = f"({total})" if len(parts) > 1 else total
    return f"{base} + h * {total}" + (f" / {den}.0" if den != 1 else "")


def compile_step(tableau: ButcherTableau, channels: int = 0):
    """step(f, y, h) -> next y, for y = (q1, q2, qd1, qd2, *channels) and
    f(q1, q2, qd1, qd2) -> (qdd1, qdd2, *channel rates)."""
    state = MECHANICAL + tuple(f"w{j}" for j in range(channels))
    lines = [f"def step(f, y, h):", f"    {', '.join(state)}, = y"]
    for i in range(tableau.stages):
        # Stage slopes: dq/dt is the stage velocity, the rest come from f.
        inputs = [_combination(x, tableau.a[i], [f"{k}_{j}" for j in range(i)])
                  for x, k in zip(MECHANICAL, ("v1", "v2", "a1", "a2"))]
        outputs = [f"a1_{i}", f"a2_{i}"] + [f"r{j}_{i}" for j in range(channels)]
        lines.append(f"    p1_{i}, p2_{i}, v1_{i}, v2_{i} = {', '.join(inputs)}")
        lines.append(f"    {', '.join(outputs)}, = f(p1_{i}, p2_{i}, v1_{i}, v2_{i})")
    slopes = ["v1", "v2", "a1", "a2"] + [f"r{j}" for j in range(channels)]
    final = [_combination(x, tableau.b, [f"{k}_{j}" for j in range(tableau.stages)])
             for x, k in zip(state, slopes)]
    lines.append(f"    return ({', '.join(final)},)")
    source = "\n".join(lines) + "\n"
    namespace: dict = {}
    exec(compile(source, f"<{tableau.name} step, {channels} channels>", "exec"), namespace)
    step = namespace["step"]
    step.source = source
    return step
