"""Exponential RK4 (integrator `exponential_rk4`): the winding currents' stiff decay, and the
torque they put on the joints, integrated exactly within the step.

An extra state x with x' = -lam x + N(q, q̇) (a winding: lam = R/L, N = (V - k N q̇)/L, which
does not depend on x) acts on the mechanics through a joint torque: q̈ = C(q, q̇) + B(q) x,
B = M⁻¹ k N (dynamics.response: per mode, a joint held fixed feels none). The step is an
exponential Runge-Kutta method (Hochbruck & Ostermann, Acta Numerica 2010, eq. 2.22, with
Krogstad's stages) whose linear part holds both: each current's pole -lam and the torque
B0 x on the velocities, B0 = B(q) at the step's start. That part is block triangular,
(q̇, x) -> (B0 x, -lam x), so its φ functions are closed forms in the scalar φ functions of
z = -h lam: the current's block is φ_k(z), the coupling's h B0 (φ_k(z) - φ_k(0)) / z, a
divided difference, and each of Krogstad's coefficients F(z) has one (in φ_k+1, below).
So the velocities take each stage's *exact integral* of the current, where RK4's weights
would take its stage values: a current that jumps (a driver switched on, a new command)
no longer reaches the motion through RK4's quadrature of e^(-lam t), which counts 1/6 of
the step for a transient that lasts L/R; and what stays explicit, (B(q) - B0) x and the
back-EMF in N, is what RK4 integrates well. Positions and the energy books keep RK4's
rows from the same stages, the currents Krogstad's.

Against an independent reference (test/physics/test_windings_exact.py, Radau on the
equations written apart), geared_arm's windings at h = 1 ms, tolerance 0: the positions
within about RK4's own error on the slow motion where the step with the pole alone lost
orders (bench_windings.py prints both). Without extra states it is RK4, bit for bit;
lam -> 0 it is an order-4 exponential method whose linear part is the torque alone.
"""
from __future__ import annotations

from functools import lru_cache
from math import exp

from .integrators import (RK4, ButcherTableau, combination, compile_step, exec_source,
                          final_terms, integrates_decay_exactly, stage_lines, state_names)

PHI_SERIES = 1.0     # |z| below this: the phi functions by their series (no cancellation)


def phi(z: float):
    """(e^z, phi1(z) ... phi4(z)) with phi_k(z) = sum_n z^n / (n + k)!."""
    if z > -PHI_SERIES:
        p4, term, power = 0.0, 1.0, 1.0
        for n in range(4, 24):       # 1/n! ... |z|^19/23! < 1e-22 at |z| = 1
            term /= n if n > 4 else 24.0
            p4 = p4 + term * power
            power = power * z        # z^(n-4) by products: pow differs in numba and libm
        p3 = 1.0 / 6.0 + z * p4
        p2 = 0.5 + z * p3
        p1 = 1.0 + z * p2
        return 1.0 + z * p1, p1, p2, p3, p4
    e = exp(z)
    p1 = (e - 1.0) / z
    p2 = (p1 - 1.0) / z
    p3 = (p2 - 0.5) / z
    return e, p1, p2, p3, (p3 - 1.0 / 6.0) / z


def exponential_rk4(z: float):
    """Krogstad's coefficients for the pole z = -h lam, (e^(z/2), e^z, a21, a31, a32, a41,
    a43, b1, b2, b3, b4) (a42 = 0; z = 0: RK4's), then the same eleven's divided
    differences (F(z) - F(0)) / z: the coupling block's (z = 0: their derivatives)."""
    e2, h1, h2, h3, _ = phi(0.5 * z)
    e, p1, p2, p3, p4 = phi(z)
    return (e2, e, 0.5 * h1, 0.5 * h1 - h2, h2, p1 - 2.0 * p2, 2.0 * p2,
            p1 - 3.0 * p2 + 4.0 * p3, 2.0 * p2 - 4.0 * p3, 2.0 * p2 - 4.0 * p3, 4.0 * p3 - p2,
            0.5 * h1, p1, 0.25 * h2, 0.25 * h2 - 0.5 * h3, 0.5 * h3, p2 - 2.0 * p3, 2.0 * p3,
            p2 - 3.0 * p3 + 4.0 * p4, 2.0 * p3 - 4.0 * p4, 2.0 * p3 - 4.0 * p4, 4.0 * p4 - p3)


# The names of exponential_rk4's coefficients in the step's source, and per stage 1-3 and
# the step's end: the current's (e^(cz), [a(z) by earlier stage]), the coupling's (divided
# differences), and RK4's quadrature of the stages' currents in the velocity (what the
# coupling replaces).
NAMES = ("E2", "E1", "A21", "A31", "A32", "A41", "A43", "B1", "B2", "B3", "B4",
         "DE2", "DE1", "D21", "D31", "D32", "D41", "D43", "DB1", "DB2", "DB3", "DB4")
STAGES = ((("E2", ("A21",)), ("DE2", ("D21",)), "0.5 * e{k}_0"),
          (("E2", ("A31", "A32")), ("DE2", ("D31", "D32")), "0.5 * e{k}_1"),
          (("E1", ("A41", None, "A43")), ("DE1", ("D41", None, "D43")), "e{k}_2"))
FINAL = (("E1", ("B1", "B2", "B3", "B4")), ("DE1", ("DB1", "DB2", "DB3", "DB4")),
         "(e{k}_0 + 2.0 * e{k}_1 + 2.0 * e{k}_2 + e{k}_3) / 6.0")


def _integral(k: int, part) -> str:
    """e^(cz) x_k + h sum a(z) n_k,j: the stage's exponential sum (of the current, or with the
    divided differences, of its integral over the stage for the coupling)."""
    start, weights = part
    terms = " + ".join(f"{w}_{k} * n{k}_{j}" for j, w in enumerate(weights) if w)
    return f"{start}_{k} * x{k} + h * ({terms})"


def _coupled(k: int, stage: str, coupling, rk4: str) -> str:
    """The current's exact integral over the stage less RK4's quadrature of its stage values:
    what the velocity's linear coupling adds (s_k)."""
    return f"    s{k}_{stage} = {_integral(k, coupling)} - {rk4.format(k=k)}"


def _velocities(extra: int, stage: str) -> list[str]:
    """v = v + h B0 s: the coupling's share of the stage's velocities."""
    pulls = lambda j: " + ".join(f"R{j}_{k} * s{k}_{stage}" for k in range(extra))
    return [f"    v{j}_{stage} = v{j}_{stage} + h * ({pulls(j)})" for j in (1, 2)]


def exponential_step_source(channels: int, extra: int, name: str = "step") -> str:
    """The straight-line source of the exponential RK4 step (step(f, y, h); reads the
    decay rates LAM0, LAM1 ... and COEFFICIENTS = exponential_rk4 from its globals, and
    f.response(q1, q2), B0 by extra state: dynamics.response)."""
    state = state_names(extra, channels)
    lines = [f"def {name}(f, y, h):", f"    {', '.join(state)}, = y"]
    for k in range(extra):   # (the stages' mechanics are RK4's: its tableau's lines)
        lines.append(f"    {', '.join(f'{c}_{k}' for c in NAMES)} = COEFFICIENTS(-h * LAM{k})")
    lines.append(f"    {', '.join(f'R1_{k}, R2_{k}' for k in range(extra))}, = f.response(q1, q2)")
    mechanics = [line for line in stage_lines(RK4, channels, first_given=False)
                 if "= f(" not in line]
    outputs = lambda i: ([f"a1_{i}", f"a2_{i}"] + [f"xd{k}_{i}" for k in range(extra)]
                         + [f"r{j}_{i}" for j in range(channels)])
    for i in range(4):
        lines.append(mechanics[i])
        for k in range(extra):
            if i == 0:
                lines.append(f"    e{k}_0 = x{k}")
                continue
            current, coupling, rk4 = STAGES[i - 1]
            lines.append(f"    e{k}_{i} = {_integral(k, current)}")
            lines.append(_coupled(k, str(i), coupling, rk4))
        if i and extra:
            lines += _velocities(extra, str(i))
        arguments = [f"p1_{i}", f"p2_{i}", f"v1_{i}", f"v2_{i}"] + [f"e{k}_{i}" for k in range(extra)]
        lines.append(f"    {', '.join(outputs(i))}, = f({', '.join(arguments)})")
        for k in range(extra):      # the nonlinear part N = x' + lam x at the stage
            lines.append(f"    n{k}_{i} = xd{k}_{i} + LAM{k} * e{k}_{i}")
    final = [combination(x, w, terms)
             for w, x, terms in final_terms(RK4, channels, RK4.pos_b, RK4.b, extra)]
    for k in range(extra):
        final[4 + k] = _integral(k, FINAL[0])
        lines.append(_coupled(k, "f", FINAL[1], FINAL[2]))
    for j in (2, 3):
        final[j] = f"{final[j]} + h * ({' + '.join(f'R{j - 1}_{k} * s{k}_f' for k in range(extra))})"
    lines.append(f"    return ({', '.join(final)},)")
    return "\n".join(lines) + "\n"


def linear_step(x: float, w: float, d: float, i0: float, u0: float) -> tuple:
    """(i, u) after one step (h = 1) of the winding's linear test problem i' = -x i - w u,
    u' = w i - d u from (i0, u0), as the generated step takes it: B0 = w, N = -w u, the
    rest of u' (-d u) explicit (stability.exponential_radius)."""
    c = exponential_rk4(-x)
    rows = [(c[0], (c[2],), c[11], (c[13],), (0.5,)),
            (c[0], (c[3], c[4]), c[11], (c[14], c[15]), (0.0, 0.5)),
            (c[1], (c[5], 0.0, c[6]), c[12], (c[16], 0.0, c[17]), (0.0, 0.0, 1.0)),
            (c[1], c[7:11], c[12], c[18:22], (1 / 6, 1 / 3, 1 / 3, 1 / 6))]
    i, u, n, a = [i0], [u0], [-w * u0], [w * i0 - d * u0]
    for start, weights, coupled, divided, rk4 in rows:
        i_k = start * i0 + sum(g * m for g, m in zip(weights, n))
        s_k = coupled * i0 + sum(g * m for g, m in zip(divided, n)) - sum(
            g * e for g, e in zip(rk4, i))
        u_k = u0 + sum(g * m for g, m in zip(rk4, a)) + w * s_k
        i, u, n, a = i + [i_k], u + [u_k], n + [-w * u_k], a + [w * i_k - d * u_k]
    return i[-1], u[-1]


def step_for(tableau: ButcherTableau, channels: int = 0, decay=(), **tolerances):
    """The step of `tableau` for a state with the extra states' linear `decay` rates."""
    if integrates_decay_exactly(tableau) and any(decay):
        return compile_exponential_step(channels, decay)
    return compile_step(tableau, channels, extra=len(decay), **tolerances)


def compile_exponential_step(channels: int, decay):
    """step(f, y, h) as compile_step(RK4 ...), with the extra states x_k whose rates
    f returns integrated exponentially at their linear decay rates `decay` (1/s, >= 0),
    their torque on the joints (f.response) with them."""
    source = exponential_step_source(channels, len(decay))
    namespace = {f"LAM{k}": float(lam) for k, lam in enumerate(decay)}
    namespace["COEFFICIENTS"] = lru_cache(maxsize=64)(exponential_rk4)  # h repeats: computed once
    step = exec_source(source, f"<exponential rk4 step, {len(decay)} linear, {channels} "
                       "channels>", namespace)["step"]
    step.source, step.decay = source, tuple(decay)
    step.constants = {k: v for k, v in namespace.items() if k.startswith("LAM")}
    return step
