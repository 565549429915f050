"""Stiff damping: which mechanism keeps RK4 stable, what it costs, and how close it stays to Radau.

Tables printed (timings are wall-clock on whatever else the machine runs: noisy):
1. the fast path: us per step of Simulator.step before this work (one RK4 step, no guard)
   and now (sub-step plan + non-finite guard), where plain RK4 is stable;
2. the candidate mechanisms on random damped states: sub-steps taken, time, and the worst
   energy excess over E(0) + the d = 0 drift of the same start and step (passivity);
3. the chosen mechanism against scipy's Radau (rtol 1e-11): max |q - q_Radau| over the run
   and the worst energy excess, over d x step, for the damped release and a moving start.

    python benchmarks/bench_stiff_damping.py [--trials 200] [--quick]
"""
from __future__ import annotations

import argparse
import random
import time
from math import ceil, log10

import numpy as np
from scipy.integrate import solve_ivp

from arm_sim_ros.physics import model
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.physics.stepping.stability import SUBSTEP_FRACTION, stiffness, substepping

BASE = load_scene("damped_release")
ARM = BASE.arm


class Before(Simulator):
    """Simulator.step as it was: one RK4 step, no plan, no guard."""

    def step(self):
        self.state = self._step(self._rhs, self.state, self.step_size)
        self.steps += 1


def step_cost(repeat: int, steps: int) -> None:
    print("\n1. fast path (plain RK4 stable): us per step, best of", repeat)
    print(f"{'scene':18s} {'before':>8s} {'now':>8s} {'now/before':>11s}")
    for name in ("release", "damped_release"):
        best = {}
        for _ in range(repeat):
            for label, cls in (("before", Before), ("now", Simulator)):
                sim = cls(load_scene(name))
                start = time.perf_counter()
                for _ in range(steps):
                    sim.step()
                best[label] = min(best.get(label, 1e9), (time.perf_counter() - start) / steps * 1e6)
        print(f"{name:18s} {best['before']:8.3f} {best['now']:8.3f} {best['now'] / best['before']:11.3f}")


# --- candidate mechanisms: advance(sim, y, h) -> (y, sub-steps) --------------------------------

def limit_of(sim):
    return SUBSTEP_FRACTION * sim.stability_limit


def worst_bound(sim, y, h):
    """The simulator's mechanism: sub-steps from lambda_max over all elbow angles."""
    return sim.accuracy.check(sim._rhs, y, h), sim.substeps


def current_bound(sim, y, h):
    """Sub-steps from lambda_max at the elbow angle the step starts from."""
    ratio = sim.scene.damping * h * stiffness(ARM, y[1])
    n = 1 if ratio <= sim.stability_limit else ceil(ratio / limit_of(sim))
    return substepping(sim._step, n)(sim._rhs, y, h), n


def current_adaptive(sim, y, h):
    """Each sub-step sized from lambda_max at the elbow angle it starts from."""
    d, left, n = sim.scene.damping, h, 0
    if d * h * stiffness(ARM, 0.0) <= sim.stability_limit and sim.substeps == 1:
        return sim._step(sim._rhs, y, h), 1
    while left > 0.0:
        h_sub = min(left, limit_of(sim) / (d * stiffness(ARM, y[1])))
        h_sub = left if h_sub > left * (1 - 1e-12) else h_sub
        y, left, n = sim._step(sim._rhs, y, h_sub), left - h_sub, n + 1
    return y, n


def implicit_split(sim, y, h):
    """Strang splitting: exact damping flow with M frozen for h/2, undamped RK4 for h, h/2 again.
    The damping flow removes exactly its kinetic energy, booked as dissipated."""
    d = sim.scene.damping

    def damp(y, t):
        m11, m12, m22 = model.mass_matrix(ARM, y[:2])
        mass = np.array([[m11, m12], [m12, m22]])
        w, v = np.linalg.eigh(np.linalg.inv(mass))
        u = np.array(y[2:4])
        u_new = v @ np.diag(np.exp(-d * t * w)) @ v.T @ u
        loss = 0.5 * u @ mass @ u - 0.5 * u_new @ mass @ u_new
        return (y[0], y[1], float(u_new[0]), float(u_new[1]), *y[4:-1], y[-1] + loss)

    y = damp(y, 0.5 * h)
    moved = sim.undamped._step(sim.undamped._rhs, y[:4] + y[4:-1], h)
    return damp(moved[:4] + tuple(moved[4:]) + (y[-1],), 0.5 * h), 1


MECHANISMS = {"worst-angle bound (chosen)": worst_bound, "current-angle bound": current_bound,
              "current-angle adaptive": current_adaptive, "implicit damping split": implicit_split}


def energy(y, gravity):
    return model.kinetic_energy(ARM, y[:2], y[2:4]) + model.potential_energy(ARM, y[:2], gravity)


def trajectory(sim, steps, advance):
    y, out, calls = sim.state, [sim.state], 0
    for _ in range(steps):
        y, n = advance(sim, y, sim.step_size)
        out.append(y)
        calls += n
    return out, calls


def excess_over_undamped(scene, out, steps):
    """max over k >= 1 of E_k - E_0 - (running max of the d = 0 run's rise over E_0 at step k);
    negative: the energy stayed that far below the bound throughout."""
    free = Simulator(scene.replace(damping=0.0))
    ref, _ = trajectory(free, steps, lambda s, y, h: (s._step(s._rhs, y, h), 1))
    e0 = energy(ref[0], scene.gravity)
    drift = np.maximum.accumulate(np.maximum([energy(y, scene.gravity) - e0 for y in ref], 0.0))
    rise = np.array([energy(y, scene.gravity) - e0 for y in out])
    return float(np.max((rise - drift)[1:]))


def random_case(rng, stress: bool):
    q = (rng.uniform(-4, 4), rng.uniform(-4, 4))
    qd = (rng.uniform(-20, 20), rng.uniform(-20, 20))
    h = 10 ** rng.uniform(-4, log10(0.05))
    # stress: d just below the current angle's own limit, where a bound from q2 alone says
    # "no sub-steps" yet the elbow may swing into a stiffer pose during the step
    d = (rng.uniform(1.5, 2.785) / (h * stiffness(ARM, q[1])) if stress
         else 10 ** rng.uniform(-1, 4))
    return BASE.replace(initial_positions=q, initial_velocities=qd, step_size=h, damping=d)


def run_mechanism(scene, steps, advance):
    sim = Simulator(scene)
    sim.undamped = Simulator(scene.replace(damping=0.0))
    start = time.perf_counter()
    out, calls = trajectory(sim, steps, advance)
    return out, calls, time.perf_counter() - start


def compare_mechanisms(trials: int) -> None:
    print(f"\n2. mechanisms on {trials} random damped states per draw (q in [-4,4]^2, |qd| <= 20, "
          "h in [1e-4, 0.05], 0.2 s); last column: max |q - q_Radau| over 1 s from q0 = "
          "(0.3, 1.2), qd0 = (4, -6), h = 0.01, worst of d = 50, 5000")
    print(f"{'mechanism':28s} {'draw':6s} {'sub-steps':>10s} {'time s':>8s} {'worst excess J':>15s} "
          f"{'err vs Radau':>13s}")
    moving = BASE.replace(initial_positions=(0.3, 1.2), initial_velocities=(4.0, -6.0))
    references = {d: radau(moving.replace(damping=d), np.arange(101) * 0.01) for d in (50.0, 5000.0)}
    for stress in (False, True):
        rng = random.Random(1)
        cases = [random_case(rng, stress) for _ in range(trials)]
        for name, advance in MECHANISMS.items():
            calls, seconds, worst = 0, 0.0, -np.inf
            for scene in cases:
                steps = max(1, round(0.2 / scene.step_size))
                out, n, took = run_mechanism(scene, steps, advance)
                calls, seconds = calls + n, seconds + took
                worst = max(worst, excess_over_undamped(scene, out, steps))
            err = max(float(np.max(np.abs(np.array(
                [y[:2] for y in run_mechanism(moving.replace(damping=d), 100, advance)[0]])
                - ref[:, :2]))) for d, ref in references.items())
            print(f"{name:28s} {'near' if stress else 'log-d':6s} {calls:10d} {seconds:8.2f} "
                  f"{worst:15.3e} {err:13.1e}")


def radau(scene, times):
    def f(_, s):
        a1, a2 = model.forward_dynamics(ARM, s[:2], s[2:], gravity=scene.gravity, damping=scene.damping)
        return [s[2], s[3], a1, a2]

    y0 = [*scene.initial_positions, *scene.initial_velocities]
    return solve_ivp(f, (0.0, times[-1]), y0, method="Radau", rtol=1e-11, atol=1e-12,
                     t_eval=times).y.T


def error_table(title, scene, duration, dampings, steps_sizes) -> None:
    print(f"\n3. {title}: per cell, max |q - q_Radau| rad over {duration:g} s / worst energy "
          "excess J (over E(0) + the d = 0 drift; < 0: passive) / max |balance residual| J / "
          "sub-steps per step")
    print(f"{'d':>8s} " + " ".join(f"{'h = ' + format(h, 'g'):>38s}" for h in steps_sizes))
    for d in dampings:
        cells = []
        for h in steps_sizes:
            case = scene.replace(damping=d, step_size=h)
            steps = round(duration / h)
            sim = Simulator(case)
            out, _ = trajectory(sim, steps, worst_bound)
            ref = radau(case, np.arange(steps + 1) * h)
            err = float(np.max(np.abs(np.array([y[:2] for y in out]) - ref[:, :2])))
            e0 = energy(out[0], case.gravity)
            books = max(abs(energy(y, case.gravity) - e0 + y[-1]) for y in out) if d else 0.0
            cells.append(f"{err:8.1e} {excess_over_undamped(case, out, steps):9.1e} {books:8.1e} "
                         f"{sim.substeps:5d}")
        print(f"{d:8g} " + " ".join(f"{c:>38s}" for c in cells))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=200)
    parser.add_argument("--quick", action="store_true", help="fewer trials and table cells")
    args = parser.parse_args()
    trials = 30 if args.quick else args.trials
    step_cost(repeat=3 if args.quick else 7, steps=20000)
    compare_mechanisms(trials)
    dampings = (0.0, 0.5, 5.0, 18.5, 50.0, 500.0, 5000.0, 1e4)
    steps_sizes = (1e-3, 0.05) if args.quick else (1e-4, 1e-3, 0.01, 0.05)
    error_table("damped release (rest, horizontal)", BASE, 2.0, dampings, steps_sizes)
    moving = BASE.replace(initial_positions=(0.3, 1.2), initial_velocities=(4.0, -6.0))
    error_table("moving start q0 = (0.3, 1.2), qd0 = (4, -6)", moving, 1.0, dampings, steps_sizes)


if __name__ == "__main__":
    main()
