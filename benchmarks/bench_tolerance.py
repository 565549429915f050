"""What the default tolerance costs against tolerance 0 on every preset and on long hard runs
(the 60 s undamped bounce between stiff compliant stops, geared_arm over 120 s); µs per
step on `release` with the error estimate (accuracy.py: estimate only, and at the default
tolerance) versus the plain planned step with no check; and the price list: time vs
achieved energy drift for a sweep of tolerances on a 100 rad/s spin (gravity off, elbow
bent 0.5 rad, 5 s). Prints tables; never pass/fail.

    .venv/bin/python benchmarks/bench_tolerance.py
    ARM_SIM_COMPILED=0 .venv/bin/python benchmarks/bench_tolerance.py   # accuracy.md's tables

On the compiled path a short run's CPU time is mostly a kernel's first load in the process.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # the sibling benchmark scripts

from bench_core import time_simulator  # noqa: E402  (best-of-repeats Simulator.step timing)

from arm_sim_ros.physics.trust.accuracy import DEFAULT_TOLERANCE  # noqa: E402
from arm_sim_ros.physics.scene import Scene, load_scene, preset_names  # noqa: E402
from arm_sim_ros.physics.simulator import Simulator  # noqa: E402


def interleaved(sims, steps=200, repeats=40) -> list[float]:
    """Best µs per step of each simulator, timed in turn (load on a shared machine hits all)."""
    best = [float("inf")] * len(sims)
    for _ in range(repeats):
        for i, sim in enumerate(sims):
            best[i] = min(best[i], time_simulator(sim, steps, 1))
    return best


def unchecked(sim) -> None:
    """The planned step alone: no check ever falls due (what a step cost before issue 14)."""
    sim.accuracy.reset()
    sim.accuracy.due = 2 ** 62    # an index no run reaches (an int: the compiled step packs it)


def cpu_run(scene, duration) -> tuple[float, Simulator]:
    """Process seconds for `duration` simulated seconds of `scene`, and the simulator."""
    sim = Simulator(scene)
    start = time.process_time()
    sim.run(duration)
    return time.process_time() - start, sim


def against_tolerance_0(cases) -> None:
    """Each case at tolerance 0 and at the default, side by side in one run."""
    print(f"  {'scene':34s} {'s':>5s} {'CPU tol 0':>10s} {'CPU default':>12s} {'ratio':>6s} "
          f"{'tol 0 meets it':>15s} {'accum. tol 0':>13s} {'accum. default':>15s}")
    for label, scene, duration in cases:
        plain_cpu, plain = cpu_run(scene.replace(tolerance=0.0), duration)
        cpu, sim = cpu_run(scene.replace(tolerance=DEFAULT_TOLERANCE), duration)
        meets = plain.accumulated_error <= DEFAULT_TOLERANCE * duration
        print(f"  {label:34s} {duration:5g} {plain_cpu:10.3f} {cpu:12.3f} "
              f"{cpu / max(plain_cpu, 1e-9):6.2f} {'yes' if meets else 'no':>15s} "
              f"{plain.accumulated_error:13.3g} {sim.accumulated_error:15.3g}")


def main() -> None:
    print(f"the default tolerance {DEFAULT_TOLERANCE:g} against tolerance 0 (CPU seconds, "
          "process time; 'tol 0 meets it': its accumulated estimate is within the tolerance "
          "x duration)")
    bounce = load_scene("compliant_limit").replace(
        **{"joint_limits.stiffness": 1e7, "joint_limits.damping": 0.0}, step_size=0.05)
    against_tolerance_0([(name, load_scene(name), max(2.0, load_scene(name).duration))
                         for name in preset_names()]
                        + [("bounce k = 1e7, h = 0.05, undamped", bounce, 60.0),
                           ("geared_arm", load_scene("geared_arm"), 120.0)])
    print()
    print("release, h = 0.01, 2 s (the explainer's figure: no sub-steps needed), µs per step,"
          " best of 40 interleaved runs")
    labels, sims = [], []
    for label, tolerance in (("plain step, no estimate", None), ("estimate only (tolerance 0)", 0.0),
                             (f"default tolerance {DEFAULT_TOLERANCE:g}", DEFAULT_TOLERANCE)):
        sim = Simulator(load_scene("release").replace(tolerance=tolerance or 0.0))
        if tolerance is None:
            sim.reset = lambda s=sim, reset=sim.reset: (reset(), unchecked(s))
        labels.append(label)
        sims.append(sim)
    costs = interleaved(sims)
    for label, cost, sim in zip(labels, costs, sims):
        print(f"  {label:32s} {cost:7.2f} us/step  ({100 * (cost / costs[0] - 1):+.1f} %)  "
              f"sub-steps {sim.substeps_taken}")
    print()
    print("price list: spin 100 rad/s, elbow 0.5 rad, gravity off, 5 s")
    print(f"  {'h':>6} {'tolerance':>10} {'sub-steps':>10} {'CPU s':>7} {'rel. drift':>11} "
          f"{'accumulated':>12}")
    for h in (0.001, 0.01):
        for tolerance in (0.0, 1e-2, 2e-3, 5e-4, 1e-4, DEFAULT_TOLERANCE, 1e-5):
            sim = Simulator(Scene(initial_positions=(0.0, 0.5), initial_velocities=(100.0, 0.0),
                                  gravity=0.0, step_size=h, tolerance=tolerance))
            e0, drift = sim.energy(sim.state), [0.0]
            start = time.process_time()
            sim.run(5.0, lambda s: drift.__setitem__(0, max(drift[0], abs(s.energy(s.state) - e0))))
            cpu = time.process_time() - start
            print(f"  {h:>6g} {tolerance:>10g} {sim.substeps_taken:>10d} {cpu:>7.2f} "
                  f"{drift[0] / e0:>11.2e} {sim.accumulated_error:>12.3g}")


if __name__ == "__main__":
    main()
