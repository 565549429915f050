"""µs per RK4 step for every preset, side by side with plain-float RK4 timed in the same run.

Baselines: the explainer's program as printed (lists, a dict per slope) and a tuned
plain-float version of the same math (tuples, unrolled RK4, no accounting). Ours carries
actuator work and dissipated energy as extra state where the scene has those effects.
A second table shows what an absent effect saves: the same scene with the effect present
at vanishing strength, i.e. what "a term multiplied by zero" would cost.

    python benchmarks/bench_core.py [--steps 20000] [--repeat 5]
"""
from __future__ import annotations

import argparse
import sys
import time
from math import cos, sin
from pathlib import Path

from arm_sim_ros.physics.scene import load_scene, preset_names
from arm_sim_ros.physics.simulator import Simulator


def explainer_step(h, gravity=9.81, damping=0.0, policy="zero", torque=(1, 0), frozen=(0, 0)):
    """The explainer's slope/offset/RK4 code, verbatim apart from returning a step function."""
    def terms(s):
        a, b, u, v = s
        m11 = 5 / 3 + cos(b)
        m12 = 1 / 3 + 0.5 * cos(b)
        m22 = 1 / 3
        c = (-0.5 * sin(b) * (2 * u * v + v * v), 0.5 * sin(b) * u * u)
        g = (gravity * (1.5 * cos(a) + 0.5 * cos(a + b)), gravity * 0.5 * cos(a + b))
        energy = 0.5 * (m11 * u * u + 2 * m12 * u * v + m22 * v * v)
        energy += gravity * (1.5 * sin(a) + 0.5 * sin(a + b))
        return m11, m12, m22, c, g, energy

    def slope(at):
        m11, m12, m22, c, g, _ = terms(at)
        applied = {"zero": (0, 0), "constant": torque, "gravity": g, "frozen": frozen}[policy]
        r1 = applied[0] - c[0] - g[0] - damping * at[2]
        r2 = applied[1] - c[1] - g[1] - damping * at[3]
        elbow = (r2 - m12 * r1 / m11) / (m22 - m12 * m12 / m11)
        shoulder = (r1 - m12 * elbow) / m11
        return [at[2], at[3], shoulder, elbow]

    def offset(at, k, scale):
        return [x + scale * dx for x, dx in zip(at, k)]

    def step(s):
        k1 = slope(s)
        k2 = slope(offset(s, k1, h / 2))
        k3 = slope(offset(s, k2, h / 2))
        k4 = slope(offset(s, k3, h))
        return [s[i] + h * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]) / 6 for i in range(4)]
    return step


def tuned_step(h, gravity=9.81):
    """The explainer's rods and unpowered release in tight plain floats: the bar to beat."""
    def slope(a, b, u, v):
        cb = cos(b)
        m11 = 5 / 3 + cb
        m12 = 1 / 3 + 0.5 * cb
        sb = 0.5 * sin(b)
        g2 = gravity * 0.5 * cos(a + b)
        r1 = sb * (2 * u * v + v * v) - gravity * 1.5 * cos(a) - g2
        r2 = -sb * u * u - g2
        elbow = (r2 - m12 * r1 / m11) / (1 / 3 - m12 * m12 / m11)
        return (r1 - m12 * elbow) / m11, elbow

    def step(s):
        a, b, u, v = s
        x1, y1 = slope(a, b, u, v)
        x2, y2 = slope(a + h / 2 * u, b + h / 2 * v, u + h / 2 * x1, v + h / 2 * y1)
        u2, v2 = u + h / 2 * x1, v + h / 2 * y1
        x3, y3 = slope(a + h / 2 * u2, b + h / 2 * v2, u + h / 2 * x2, v + h / 2 * y2)
        u3, v3 = u + h / 2 * x2, v + h / 2 * y2
        x4, y4 = slope(a + h * u3, b + h * v3, u + h * x3, v + h * y3)
        u4, v4 = u + h * x3, v + h * y3
        return (a + h * (u + 2 * u2 + 2 * u3 + u4) / 6, b + h * (v + 2 * v2 + 2 * v3 + v4) / 6,
                u + h * (x1 + 2 * x2 + 2 * x3 + x4) / 6, v + h * (y1 + 2 * y2 + 2 * y3 + y4) / 6)
    return step


def time_loop(step, state, steps, repeat) -> float:
    """Best of `repeat` runs, µs per step."""
    best = float("inf")
    for _ in range(repeat):
        s = state
        start = time.perf_counter()
        for _ in range(steps):
            s = step(s)
        best = min(best, time.perf_counter() - start)
    return best / steps * 1e6


def fastest(run, repeat: int, setup=None) -> float:
    """Wall seconds of the fastest of `repeat` calls of run(), each after an untimed setup()
    if given (the benchmarks' timing)."""
    best = float("inf")
    for _ in range(repeat):
        if setup is not None:
            setup()
        start = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - start)
    return best


class TreeWorker:
    """A worker process timing on another source tree (PYTHONPATH = the tree, so that it wins
    over the editable install): `source` prints where it imported arm_sim_ros from, then for
    each line on its stdin one line of times; `best` keeps the least of each."""

    def __init__(self, tree: Path, source: str, *args: str):
        import os
        import subprocess

        env = dict(os.environ, PYTHONPATH=str(tree))
        self.process = subprocess.Popen([sys.executable, "-c", source, *args], cwd=tree,
                                        env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        text=True)
        where = Path(self.process.stdout.readline().strip() or "(the worker failed)")
        if tree.resolve() not in where.resolve().parents:
            self.close()
            sys.exit(f"--before {tree}: imported arm_sim_ros from {where}, not from the tree")
        self.best = None

    def run(self) -> None:
        self.process.stdin.write("\n")
        self.process.stdin.flush()
        times = [float(t) for t in self.process.stdout.readline().split()]
        self.best = times if self.best is None else [min(b, t) for b, t in zip(self.best, times)]

    def close(self) -> None:
        self.process.stdin.close()
        self.process.wait()


def time_simulator(scene_or_sim, steps, repeat) -> float:
    """µs per Simulator.step, the fastest of `repeat` runs of `steps` steps, each from the
    initial state (an untimed reset; a Simulator given is reused, its compiled code warm)."""
    sim = scene_or_sim if isinstance(scene_or_sim, Simulator) else Simulator(scene_or_sim)
    step = sim.step

    def run():
        for _ in range(steps):
            step()
    return fastest(run, repeat, sim.reset) / steps * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    h = 0.01
    explainer = time_loop(explainer_step(h), [0.0, 0.0, 0.0, 0.0], args.steps, args.repeat)
    tuned = time_loop(tuned_step(h), (0.0, 0.0, 0.0, 0.0), args.steps, args.repeat)
    print(f"baselines (release, h = {h}): explainer's code {explainer:.2f} µs/step, "
          f"tuned plain floats {tuned:.2f} µs/step\n")
    print("µs per Simulator.step over each preset's first steps, tolerance 0 (estimate only) "
          "and the default tolerance side by side:")
    print(f"{'preset':30s} {'effects':26s} {'tol 0':>8s} {'default':>8s} {'÷ tol 0':>8s} "
          f"{'÷ tuned':>8s} {'÷ explainer':>12s}")
    for name in preset_names():
        scene = load_scene(name)
        sim = Simulator(scene)
        plain = time_simulator(scene.replace(tolerance=0.0), args.steps, args.repeat)
        ours = time_simulator(scene, args.steps, args.repeat)
        print(f"{name:30s} {'+'.join(sim.dynamics.effects) or '-':26s} {plain:8.2f} {ours:8.2f} "
              f"{ours / plain:8.2f} {ours / tuned:8.2f} {ours / explainer:12.2f}")

    print("\nwhat an absent effect saves (absent vs present at vanishing strength):")
    print(f"{'scene':30s} {'effect':10s} {'absent µs':>10s} {'present µs':>11s} {'saving':>8s}")
    tiny = 5e-324
    for name, effect in (("shoulder_torque_no_gravity", "gravity"), ("release", "damping"),
                         ("release", "actuator")):
        scene = load_scene(name)
        present = scene.replace(**{"gravity": {"gravity": tiny}, "damping": {"damping": tiny},
                                   "actuator": {"policy": "constant"}}[effect])
        absent_us = time_simulator(scene, args.steps, args.repeat)
        present_us = time_simulator(present, args.steps, args.repeat)
        print(f"{name:30s} {effect:10s} {absent_us:10.2f} {present_us:11.2f} "
              f"{1 - absent_us / present_us:8.0%}")


if __name__ == "__main__":
    main()
