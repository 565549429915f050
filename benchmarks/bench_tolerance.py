"""µs per step on `release` with the error estimate (accuracy.py) versus the plain planned
step, and the price list: time vs achieved energy drift for a sweep of tolerances on a
100 rad/s spin (gravity off, elbow bent 0.5 rad, 5 s). Prints tables; never pass/fail.

    .venv/bin/python benchmarks/bench_tolerance.py
"""
from __future__ import annotations

import time

from arm_sim_ros.physics.scene import Scene, load_scene
from arm_sim_ros.physics.simulator import Simulator


def per_step(sim, steps=2000, repeats=5) -> float:
    best = float("inf")
    for _ in range(repeats):
        sim.reset()
        start = time.perf_counter()
        for _ in range(steps):
            sim.step()
        best = min(best, time.perf_counter() - start)
    return best / steps * 1e6


def main() -> None:
    sim = Simulator(load_scene("release"))
    checked = per_step(sim)
    plain_advance = sim.accuracy.advance
    sim._advance = sim.accuracy.step      # noqa: SLF001  the step without the books (before)
    plain = per_step(sim)
    sim._advance = plain_advance
    print("release, h = 0.01 (no sub-steps needed)")
    print(f"  before (plain step):       {plain:7.2f} us/step")
    print(f"  after (estimate, checks):  {checked:7.2f} us/step  (+{100 * (checked / plain - 1):.0f} %)")
    print()
    print("price list: spin 100 rad/s, elbow 0.5 rad, gravity off, 5 s")
    print(f"  {'h':>6} {'tolerance':>10} {'sub-steps':>10} {'CPU s':>7} {'rel. drift':>11} "
          f"{'accumulated':>12}")
    for h in (0.001, 0.01):
        for tolerance in (0.0, 1e-1, 5e-2, 1e-2, 5e-3, 2e-3, 1e-3, 1e-4):
            sim = Simulator(Scene(initial_positions=(0.0, 0.5), initial_velocities=(100.0, 0.0),
                                  gravity=0.0, step_size=h, tolerance=tolerance))
            e0, drift = sim.energy(sim.state), [0.0]
            start = time.perf_counter()
            sim.run(5.0, lambda s: drift.__setitem__(0, max(drift[0], abs(s.energy(s.state) - e0))))
            cpu = time.perf_counter() - start
            print(f"  {h:>6g} {tolerance:>10g} {sim.substeps_taken:>10d} {cpu:>7.2f} "
                  f"{drift[0] / e0:>11.2e} {sim.accumulated_error:>12.3g}")


if __name__ == "__main__":
    main()
