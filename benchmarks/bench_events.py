"""Friction and joint limits: what event handling costs, and what it buys.

Tables printed (timings are wall-clock on whatever else the machine runs: noisy):
1. us per step of Simulator.step for each switching preset beside the same scene without
   friction and joint limits (no switching code at all), with the switches it met;
2. the cost of watching for switches when none happens (an arm stuck at rest, an arm
   swinging far from its limits);
3. convergence: the error at T against a reference and the fitted order, with event
   location and with switching at sub-step ends (`sim.switching.locate = False`). The
   reference here is the located run at h = 0.01 / 256 (test_friction_limits.py checks the
   same orders against an independent solve_ivp(events=...) reference);
4. sub-steps a compliant limit takes while engaged, over k and h (0 switching cost while
   no joint is beyond its limit);
5. what reading the guards between a sub-step's ends costs (physics/switching/dense.py: a mode that
   ends and comes back within one sub-step), against reading them at its end only, the
   two interleaved in one process.

    python benchmarks/bench_events.py [--quick]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))   # the sibling benchmark scripts

from bench_core import time_simulator  # noqa: E402  (best-of-repeats Simulator.step timing)

from arm_sim_ros.physics.switching import dense, events  # noqa: E402
from arm_sim_ros.physics.scene import load_scene  # noqa: E402
from arm_sim_ros.physics.simulator import Simulator  # noqa: E402


def per_step(scene, seconds: float, repeat: int = 3):
    """(best us per step over `repeat` runs after a warm-up, switch counts of the last). The
    same simulator is reset between runs: each mode's right-hand side is compiled once, on
    first use."""
    sim = Simulator(scene)
    return time_simulator(sim, scene.steps_for(seconds), repeat + 1), dict(sim.switch_events)


def cost_table(quick: bool) -> None:
    print("1. us per step: with switching effects vs the same scene without them")
    print(f"{'scene':<34}{'with':>9}{'without':>9}{'ratio':>7}  switches")
    rows = [("stick_slip", 6.0), ("limit_impact", 3.0), ("compliant_limit", 3.0),
            ("geared_arm", 1.0)]
    for name, seconds in rows:
        scene = load_scene(name)
        seconds = seconds / 2 if quick else seconds
        with_, counts = per_step(scene, seconds)
        without, _ = per_step(scene.replace(friction=None, joint_limits=None), seconds)
        print(f"{name + f' ({seconds:g} s, h={scene.step_size:g})':<34}{with_:>9.1f}"
              f"{without:>9.1f}{with_ / without:>7.2f}  {counts}")
    print()
    print("2. us per step when no switch happens")
    release = load_scene("release")
    cases = [
        ("stuck at rest (friction, cone holds)",
         release.replace(initial_positions=(0.3, 0.5),
                         friction={"coulomb": [15.0, 4.0], "static": [20.0, 6.0]}),
         release.replace(initial_positions=(0.3, 0.5), gravity=0.0)),
        ("swinging, limits never reached",
         release.replace(joint_limits={"lower": [-10.0, -10.0], "upper": [10.0, 10.0]}), release),
        ("swinging, compliant limits never reached",
         release.replace(joint_limits={"lower": [-10.0, -10.0], "upper": [10.0, 10.0],
                                       "stiffness": 1e6, "damping": 10.0}), release),
    ]
    print(f"{'case':<42}{'with':>9}{'plain':>9}{'ratio':>7}")
    for label, scene, plain in cases:
        seconds = 1.0 if quick else 3.0
        with_, counts = per_step(scene, seconds)
        without, _ = per_step(plain, seconds)
        assert not counts, counts
        print(f"{label:<42}{with_:>9.1f}{without:>9.1f}{with_ / without:>7.2f}")
    print()


STEPS = (0.01, 0.005, 0.0025, 0.00125)
UNLOCATED_STEPS = tuple(0.01 / 2 ** n for n in range(7))
CONVERGENCE = {
    "stick-slip (stick_slip, vs = 0, T = 1.5 s)": (load_scene("stick_slip").replace(
        friction={"coulomb": [3.0, 0.5], "static": [4.0, 0.8]}), 1.5),
    "impact (limit_impact, e = 0.5, T = 0.78 s)": (load_scene("limit_impact"), 0.78),
}


def run_to(scene, h, T, locate=True):
    sim = Simulator(scene.replace(step_size=h))
    sim.switching.locate = locate
    sim.run(T)
    return np.array(sim.state[:4]), sum(sim.switch_events.values())


def convergence_table() -> list[str]:
    lines = ["3. convergence: max |state - reference| at T, and the fitted order",
             f"{'case':<44}{'h':>10}{'located':>11}{'at sub-step end':>17}"]
    for label, (scene, T) in CONVERGENCE.items():
        exact, _ = run_to(scene, 0.01 / 256, T)
        located = [float(np.max(np.abs(run_to(scene, h, T)[0] - exact))) for h in STEPS]
        late = [float(np.max(np.abs(run_to(scene, h, T, False)[0] - exact)))
                for h in UNLOCATED_STEPS]
        for n, h in enumerate(UNLOCATED_STEPS):
            first = label if n == 0 else ""
            loc = f"{located[n]:.2e}" if n < len(STEPS) else ""
            lines.append(f"{first:<44}{h:>10.6g}{loc:>11}{late[n]:>17.2e}")
        order = np.polyfit(np.log(STEPS), np.log(located), 1)[0]
        late_order = np.polyfit(np.log(UNLOCATED_STEPS), np.log(late), 1)[0]
        lines.append(f"{'  fitted order':<44}{'':>10}{order:>11.2f}{late_order:>17.2f}")
    return lines


def substep_table() -> list[str]:
    lines = ["4. sub-steps per step while a compliant limit is engaged (1 = plain RK4)",
             f"{'k (N m/rad)':<14}" + "".join(f"{f'h={h:g}':>10}" for h in (1e-4, 1e-3, 1e-2, 0.05))]
    for k in (1e4, 1e5, 1e6, 1e7):
        cells = []
        for h in (1e-4, 1e-3, 1e-2, 0.05):
            sim = Simulator(load_scene("compliant_limit").replace(
                step_size=h, **{"joint_limits.stiffness": k}))
            cells.append(f"{sim.switching.substeps_for(h, True):>10d}")
        lines.append(f"{k:<14.0e}" + "".join(cells))
    return lines


def end_only(step, rhs, guard, width, y0, y1, dt):
    """dense.ended as it was: the guards at the sub-step's end only."""
    values = guard(*y1[:width])
    return None if not values or min(values) >= 0.0 else dt


def dense_table(quick: bool) -> list[str]:
    release = load_scene("release")
    cases = [(name, load_scene(name), seconds) for name, seconds in
             (("stick_slip", 6.0), ("limit_impact", 3.0), ("compliant_limit", 3.0))] + [
        ("stuck at rest (friction)", release.replace(
            initial_positions=(0.3, 0.5), friction={"coulomb": [15.0, 4.0], "static": [20.0, 6.0]}),
         3.0),
        ("swinging, limits never reached", release.replace(
            joint_limits={"lower": [-10.0, -10.0], "upper": [10.0, 10.0]}), 3.0)]
    lines = ["5. us per step: guards read at the sub-step's end only vs also between its ends",
             f"{'scene':<34}{'end only':>10}{'between':>10}{'ratio':>7}"]
    for label, scene, seconds in cases:
        seconds = seconds / 2 if quick else seconds
        best = {}
        for _ in range(3):
            for check in (end_only, dense.ended):
                events.ended = check
                cost, _ = per_step(scene, seconds, 1)
                best[check] = min(best.get(check, cost), cost)
        events.ended = dense.ended
        lines.append(f"{label:<34}{best[end_only]:>10.1f}{best[dense.ended]:>10.1f}"
                     f"{best[dense.ended] / best[end_only]:>7.2f}")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter timing runs")
    args = parser.parse_args()
    cost_table(args.quick)
    print("\n".join(convergence_table()))
    print()
    print("\n".join(substep_table()))
    print()
    print("\n".join(dense_table(args.quick)))


if __name__ == "__main__":
    main()
