"""geared_arm's windings, rk4 with its planned sub-steps against exponential_rk4 (none):
the order in the mechanics against test_effects' independent first-principles reference,
the energy books, the tolerance's sub-steps and the error against a tight-tolerance run,
and cost per simulated second on the pure-Python and the compiled path; stiff windings
(L/R 10 µs to 1 ms, no method named, beside rk4 named): error against the reference on
Radau and price, with `--base DIR` another checkout's price beside (main's), timed in the
same rounds. Prints tables; never pass/fail. `--dcmotor` adds bench_speed's windings
table (MuJoCo's first-order dcmotor at equal h; needs the bench extra); `--linear-parts`
a study of the exponential step with more of the winding's coupling in its exactly
integrated part (errors only: it takes scipy's expm per step).

    nice python benchmarks/bench_windings.py [--repeat 3] [--base DIR] [--tables stiff,...]
        [--dcmotor] [--linear-parts]     (a study named alone runs alone; --tables adds to it)
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))                  # the sibling benchmark scripts
sys.path.insert(1, str(HERE.parent / "test"))  # test_effects' FirstPrinciples

from bench_speed import fastest, simulator  # noqa: E402
from physics.test_effects import FirstPrinciples  # noqa: E402

from arm_sim_ros.physics.compiled import build as compiled  # noqa: E402
from arm_sim_ros.physics.scene import load_scene  # noqa: E402

METHODS = ("rk4", "exponential_rk4")
SHIPPED = load_scene("geared_arm")
SMOOTH = SHIPPED.replace(friction=None, joint_limits=None, tolerance=0.0)
CASES = (("held", SMOOTH, (0.0, 0.0)),
         ("moving", SMOOTH.replace(initial_velocities=(0.5, -1.0)), (10.0, -4.0)))


def convergence(seconds: float = 0.2) -> list[str]:
    """|q|, |qd| error at t = `seconds` against FirstPrinciples (DOP853 at 1e-12), each
    method at tolerance 0 (the methods alone), the observed order, and the books' largest
    |E - E0 - inputs + losses| over the run."""
    lines = [f"geared_arm without friction and limits, tolerance 0, t = {seconds:g} s: error "
             "against the first-principles reference, order, largest |books residual| (J)"]
    for label, scene, command in CASES:
        reference = FirstPrinciples(scene, command=command).solve(seconds)
        lines.append(f"{label} (command {command[0]:g}, {command[1]:g} N m on gravity "
                     f"compensation, qd0 = {scene.initial_velocities})")
        lines.append(f"{'h (ms)':>7} |" + " |".join(
            f" {m[:7]:>7} sub  |q err| |qd err| order   books" for m in METHODS))
        previous = {}
        for h in (4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4):
            row = f"{h * 1e3:>7g} |"
            for method in METHODS:
                sim = simulator(scene.replace(step_size=h, integrator=method), False)
                sim.set_command(*command)
                books = sim.run(seconds)
                q = float(np.max(np.abs(np.array(sim.state[0:2]) - reference[0:2])))
                qd = float(np.max(np.abs(np.array(sim.state[2:4]) - reference[2:4])))
                order = (f"{math.log2(previous[method] / qd):5.1f}"    # (not at rounding)
                         if method in previous and qd > 1e-10 else "     ")
                previous[method] = qd
                row += f" {sim.substeps:>11d} {q:8.1e} {qd:8.1e} {order} {books:7.1e} |"
            lines.append(row.rstrip(" |"))
    return lines


def books_by_channel(h: float = 1e-3, seconds: float = 0.2) -> list[str]:
    """Each book's error against FirstPrinciples' own (integrated with the motion by DOP853),
    and E's: which quadrature leaves the residual (tolerance 0)."""
    from physics.test_effects import BOOKS
    lines = [f"books at t = {seconds:g} s, h = {h * 1e3:g} ms, tolerance 0: ours - reference (J)",
             f"{'':7}{'method':<16}" + "".join(f"{b:>18}" for b in BOOKS) + f"{'E':>10}"
             f"{'residual':>10}"]
    for label, scene, command in CASES:
        truth = FirstPrinciples(scene, command=command)
        reference = truth.solve(seconds)
        exact = dict(zip(BOOKS, reference[-len(BOOKS):]))
        for method in METHODS:
            sim = simulator(scene.replace(step_size=h, integrator=method), False)
            sim.set_command(*command)
            sim.run(seconds)
            books = sim.channel_values(sim.state)
            lines.append(f"{label:<7}{method:<16}"
                         + "".join(f"{books[b] - exact[b]:>18.1e}" for b in BOOKS)
                         + f"{sim.energy(sim.state) - truth.energy(reference):>10.1e}"
                         + f"{sim.residual():>10.1e}")
    return lines


def under_tolerance(seconds: float, repeat: int) -> list[str]:
    """geared_arm as shipped (friction, limits, clamps, default tolerance), from rest, held
    and commanded: the plan, the sub-steps per step the run took, |q, qd - reference| (rk4
    at tolerance 1e-10), the global estimate, the books' largest residual and µs per
    simulated second on each path. sub/step: the sub-steps run in split steps (planned or
    the tolerance's), per step; 0 = plain steps."""
    paths = [False] + ([True] if compiled.available() else [])
    lines = [f"geared_arm as shipped, default tolerance {SHIPPED.tolerance:g} per s, {seconds:g} s "
             f"from rest; reference: rk4 at tolerance 1e-10; µs per simulated second, best of "
             f"{repeat}",
             f"{'':10}{'method':<16}{'plan':>5}{'sub/step':>9}{'|q-ref|':>9}{'estimate':>9}"
             f"{'books':>9}{'python':>9}{'compiled':>9}"]
    for label, command in (("held", (0.0, 0.0)), ("commanded", (10.0, -4.0))):
        tight = simulator(SHIPPED.replace(integrator="rk4", tolerance=1e-10), False)
        tight.set_command(*command)
        tight.run(seconds)
        for method in METHODS:
            scene = SHIPPED.replace(integrator=method)
            costs = []
            for fast in paths:
                sim = simulator(scene, fast)

                def run(sim=sim):
                    sim.reset()
                    sim.set_command(*command)
                    return sim.run(seconds)
                books = run()                     # (and compiles what the run meets)
                costs.append(fastest(run, repeat) / seconds * 1e6)
            error = max(abs(a - b) for a, b in zip(sim.state[:4], tight.state[:4]))
            cost = "".join(f"{c:>9.0f}" for c in costs) + ("" if len(costs) > 1 else f"{'-':>9}")
            lines.append(f"{label:<10}{method:<16}{sim.substeps:>5d}"
                         f"{sim.substeps_taken / sim.steps:>9.2f}"
                         f"{error:>9.1e}{sim.accumulated_error:>9.1e}{books:>9.1e}{cost}")
    return lines


# --- What else the exactly integrated part could hold (a study, not the shipped step) ------
#
# Krogstad's stages with a matrix linear part A (Hochbruck & Ostermann 2010, eq. 2.22):
# stage = e^(cZ) y + h sum a(Z) N, N = f(y) - A y, Z = hA, φ functions by scipy's expm of an
# augmented matrix. A is frozen at each step's start; which couplings it holds:
PARTS = {
    "decay": "the winding's own pole -R/L (the step before issue 47)",
    "torque (shipped)": "+ the currents' torque on qd, the whole M^-1 (no back-EMF)",
    "per joint": "+ i <-> qd of the same joint, M^-1's diagonal",
    "coupled": "+ i <-> qd with the whole M^-1 (cross terms)",
    "coupled + q": "+ q' = qd",
    "Jacobian": "the whole linearisation (exponential Rosenbrock-like)",
}


def _phi(z, k):
    from scipy.linalg import expm
    n = len(z)
    augmented = np.zeros((n * (k + 1), n * (k + 1)))
    augmented[:n, :n] = z
    for j in range(k):
        augmented[n * j:n * (j + 1), n * (j + 1):n * (j + 2)] = np.eye(n)
    e = expm(augmented)
    return [e[:n, n * j:n * (j + 1)] for j in range(k + 1)]


def _linear_part(sim, y, part):
    """A (q1 q2 qd1 qd2 i1 i2, then channels) at y: the couplings `part` names, from a
    difference quotient of the generated right-hand side (exact for the linear ones)."""
    def slope(y):
        return np.array([y[2], y[3], *sim.dynamics.function(*y[:6])[:4]])
    jacobian, base = np.zeros((6, 6)), slope(y)
    for k in range(6):
        moved = np.array(y[:6], float)
        moved[k] += 1e-7 * max(1.0, abs(moved[k]))
        jacobian[:, k] = (slope(moved) - base) / (moved[k] - y[k])
    a = np.zeros((len(y), len(y)))
    if part == "Jacobian":
        a[:6, :6] = jacobian
        return a
    a[4, 4], a[5, 5] = -sim.dynamics.decay[0], -sim.dynamics.decay[1]
    if part == "decay":
        return a
    if part == "torque (shipped)":
        a[2:4, 4:6] = jacobian[2:4, 4:6]
        return a
    a[4, 2], a[5, 3] = jacobian[4, 2], jacobian[5, 3]          # -kN/L: the back-EMF
    if part == "per joint":
        a[2, 4], a[3, 5] = jacobian[2, 4], jacobian[3, 5]      # kN (M^-1)jj: the torque
    else:
        a[2:4, 4:6] = jacobian[2:4, 4:6]
    if part == "coupled + q":
        a[0, 2] = a[1, 3] = 1.0
    return a


def _krogstad(sim, y, h, part):
    a = _linear_part(sim, y, part)

    def rest(y):
        return np.array([y[2], y[3], *sim.dynamics.function(*y[:6])]) - a @ y
    e2, p21, p22 = _phi(0.5 * h * a, 2)
    e1, p1, p2, p3 = _phi(h * a, 3)
    n0 = rest(y)
    n1 = rest(e2 @ y + h * (0.5 * p21) @ n0)
    n2 = rest(e2 @ y + h * ((0.5 * p21 - p22) @ n0 + p22 @ n1))
    n3 = rest(e1 @ y + h * ((p1 - 2 * p2) @ n0 + 2 * p2 @ n2))
    return e1 @ y + h * ((p1 - 3 * p2 + 4 * p3) @ n0 + (2 * p2 - 4 * p3) @ (n1 + n2)
                         + (4 * p3 - p2) @ n3)


def _hochbruck_ostermann(sim, y, h, part):
    """Their 5-stage method of stiff order 4 (BIT 2005, eq. 5.19): one more stage."""
    a = _linear_part(sim, y, part)

    def rest(y):
        return np.array([y[2], y[3], *sim.dynamics.function(*y[:6])]) - a @ y
    e2, p12, p22, p32 = _phi(0.5 * h * a, 3)
    e1, p1, p2, p3 = _phi(h * a, 3)
    n1 = rest(y)
    n2 = rest(e2 @ y + h * (0.5 * p12) @ n1)
    n3 = rest(e2 @ y + h * ((0.5 * p12 - p22) @ n1 + p22 @ n2))
    n4 = rest(e1 @ y + h * ((p1 - 2 * p2) @ n1 + p2 @ (n2 + n3)))
    a52 = 0.5 * p22 - p3 + 0.25 * p2 - 0.5 * p32
    a54 = 0.25 * p22 - a52
    n5 = rest(e2 @ y + h * ((0.5 * p12 - 2 * a52 - a54) @ n1 + a52 @ (n2 + n3) + a54 @ n4))
    return e1 @ y + h * ((p1 - 3 * p2 + 4 * p3) @ n1 + (4 * p3 - p2) @ n4
                         + (4 * p2 - 8 * p3) @ n5)


def linear_parts(seconds: float = 0.2) -> list[str]:
    """|q, qd error| at t = `seconds` against FirstPrinciples for each choice of A."""
    steps = (4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4)
    lines = ["exponential RK4 (Krogstad) with a matrix linear part A frozen at each step's "
             f"start: max |q, qd error| at t = {seconds:g} s (order), geared_arm without "
             "friction and limits",
             *(f"  {name}: {what}" for name, what in PARTS.items()),
             "  decay, HO5: the pole alone, Hochbruck & Ostermann's 5 stages (stiff order 4)"]
    for label, scene, command in CASES:
        reference = FirstPrinciples(scene, command=command).solve(seconds)
        lines.append(f"{label:<17}" + "".join(f"{h * 1e3:>13g} ms" for h in steps))
        for name in [*PARTS, "decay, HO5"]:
            part, method = ((name, _krogstad) if name in PARTS
                            else ("decay", _hochbruck_ostermann))
            row, previous = f"{name:<17}", None
            for h in steps:
                sim = simulator(scene.replace(step_size=h), False)
                sim.set_command(*command)
                y = np.array(sim.state, float)
                for _ in range(scene.steps_for(seconds, h)):
                    y = method(sim, y, h, part)
                error = float(np.max(np.abs(y[:4] - reference[:4])))
                order = f"({math.log2(previous / error):.1f})" if previous else ""
                row += f"{error:>10.1e}{order:>6}"
                previous = error
            lines.append(row)
    return lines


# --- Stiff windings: accuracy and price by L/R (issue 47) -----------------------------------

STIFF = ((1e-5, ""), (1e-5, "rk4"), (1e-4, ""), (1e-4, "rk4"), (0.301e-3 / 0.573, ""),
         (0.301e-3 / 0.573, "rk4"), (1e-3, ""), (1e-3, "rk4"))
# The arm and its windings at L/R = `constant` (None: the gears alone, no windings), moving
# and commanded, no clamps (the reference has no events), tolerance 0 (the methods alone).
# Written with the public API only: `--base` runs it in another checkout too.
SCENE = """
from arm_sim_ros.physics.scene import load_scene

def stiff_scene(constant, integrator):
    base = load_scene("geared_arm").replace(friction=None, joint_limits=None, tolerance=0.0,
                                            effort_limits=None, initial_velocities=(0.5, -1.0),
                                            integrator=integrator)
    motors = {k: v for k, v in base.motors.items() if k != "voltage_limit"}
    if constant is None:
        return base.replace(motors={k: motors[k] for k in ("gear_ratio", "rotor_inertia")})
    motors["inductance"] = [constant * r for r in motors["resistance"]]
    return base.replace(motors=motors)
"""
TIMING = SCENE + """
import json, sys, time
from arm_sim_ros.physics.simulator import Simulator
rows, seconds, command = json.loads(sys.argv[1])
out = []
for constant, integrator in rows:
    sim = Simulator(stiff_scene(constant, integrator))
    sim.set_command(*command)
    sim.run(seconds)            # compiles, or loads the kernels, once
    sim.reset()
    sim.set_command(*command)
    start = time.process_time()
    sim.run(seconds)
    out.append((time.process_time() - start) / seconds * 1e6)
print(json.dumps(out))
"""
STIFF_COMMAND = (10.0, -4.0)


def _prices(checkout: Path, rows, seconds: float, fast: bool) -> list:
    """µs per simulated second of each row, one run each, in a process of `checkout`'s."""
    env = dict(os.environ, PYTHONPATH=str(checkout), ARM_SIM_COMPILED="1" if fast else "0")
    done = subprocess.run([sys.executable, "-c", TIMING, json.dumps([rows, seconds,
                                                                     STIFF_COMMAND])],
                          cwd=checkout, env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.splitlines()[-1])


def stiff_table(seconds: float, long: float, repeat: int, base: Path | None) -> list[str]:
    """Per L/R, no method named (exponential_rk4 where the windings are stiff) beside rk4
    named: the plan's sub-steps, the largest |q| and |q, qd| error over `seconds` against
    FirstPrinciples on Radau (rtol 1e-12), and µs per simulated second of Simulator.run,
    pure Python over `seconds`, compiled over `long`, best of `repeat` rounds, each row
    once a round in a process of its checkout (with `base`, that one's too, in turn)."""
    from physics.test_windings_exact import errors_against_radau
    namespace = {}
    exec(SCENE, namespace)
    stiff_scene = namespace["stiff_scene"]
    rows = [(None, "")] + list(STIFF)
    checkouts = {"this": HERE.parent} | ({"base": base.resolve()} if base else {})
    best = {(label, fast): [math.inf] * len(rows) for label in checkouts for fast in (0, 1)}
    for _ in range(repeat):
        for label, checkout in checkouts.items():
            for fast, span in ((0, seconds), (1, long)):
                if fast and not compiled.available():
                    continue
                prices = _prices(checkout, rows, span, bool(fast))
                best[label, fast] = [min(a, b) for a, b in zip(best[label, fast], prices)]
    head = (f"geared arm (no clamps, friction or limits), h = 1 ms, tolerance 0, commanded "
            f"{STIFF_COMMAND} N m on gravity compensation from qd0 = (0.5, -1.0): largest "
            f"error over {seconds:g} s against the first-principles equations on Radau; "
            f"µs per simulated second of Simulator.run, python {seconds:g} s, compiled "
            f"{long:g} s runs, best of {repeat} rounds" + (", base: another checkout's, "
                                                           "the same rounds" if base else ""))
    lines = [head, f"{'L/R':>9} {'named':>6} {'method':>16} {'sub':>4} {'|q err|':>8} "
             f"{'|qd err|':>8} {'python':>8} {'compiled':>9} {'of gears':>8}"
             + (f" {'base py':>8} {'base comp':>9} {'this÷base':>9}" if base else "")]
    for k, (constant, integrator) in enumerate(rows):
        scene = stiff_scene(constant, integrator)
        if constant is None:
            errors, what = f"{'-':>8} {'-':>8}", "gears"
        else:
            q, state = errors_against_radau(scene, STIFF_COMMAND, seconds)
            errors, what = f"{q:8.1e} {state:8.1e}", f"{constant * 1e6:7.0f} µs"
        py, fast = best["this", 0][k], best["this", 1][k]
        line = (f"{what:>9} {integrator or '-':>6} {scene.method:>16} "
                f"{simulator(scene, False).substeps:>4} {errors} {py:8.0f} {fast:9.0f} "
                f"{fast / best['this', 1][0]:7.2f}x")
        if base:
            line += (f" {best['base', 0][k]:8.0f} {best['base', 1][k]:9.0f} "
                     f"{fast / best['base', 1][k]:8.2f}x")
        lines.append(line)
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=1.0)
    parser.add_argument("--long", type=float, default=20.0,
                        help="simulated s of the stiff table's compiled runs")
    parser.add_argument("--base", type=Path, help="another checkout (main's): its price beside")
    parser.add_argument("--tables", help="of convergence, books, tolerance, stiff (all four "
                                         "unless a study is named)")
    parser.add_argument("--dcmotor", action="store_true")
    parser.add_argument("--linear-parts", action="store_true",
                        help="the study of what else the exact part could hold (scipy)")
    args = parser.parse_args()
    # A study named alone runs alone: its command reads as it is written, with no empty
    # --tables argument to quote.
    if args.tables is None:
        args.tables = "" if args.dcmotor or args.linear_parts else \
            "convergence,books,tolerance,stiff"
    chosen = [name for name in args.tables.split(",") if name]
    tables = {"convergence": convergence, "books": books_by_channel,
              "tolerance": lambda: under_tolerance(args.seconds, args.repeat),
              "stiff": lambda: stiff_table(args.seconds, args.long, args.repeat, args.base)}
    for name in chosen:
        if name not in tables:
            parser.error(f"--tables: {name!r} is none of {', '.join(tables)}")
    chosen = [tables[name] for name in chosen]
    if args.linear_parts:
        chosen.append(linear_parts)
    if args.dcmotor:
        from bench_speed import windings_table
        chosen.append(lambda: windings_table(args.repeat))
    for table in chosen:
        print("\n".join(table()) + "\n", flush=True)


if __name__ == "__main__":
    main()
