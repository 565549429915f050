"""What sensors and command latency cost (issue 37): µs per Simulator.step, per step of
Simulator.run and per node tick, without sensors, with `sensors` that model nothing, with the
contract's full `sensors` block, and with a servo reading them under a command delay; beside
the same rows of the tree before sensors (--before DIR), timed in the same run.

Rows are timed in rounds, every row once per round in an order rotated from round to round,
each keeping its fastest of --repeat rounds of --steps steps (node: ticks of one step each,
publishing every step, the core without a transport: the JointState and the truth built).
The full block is the issue's:

    seed 7, rate 500 Hz, 4096 counts, noise 1e-4 rad, velocity differences, delay 2 ms
    (+ command_delay 1 ms on the servo rows)

--before DIR times `release`'s step and run on a checkout of the tree before sensors (`git
archive main | tar -x -C /tmp/before`, main not yet merged with this branch) and on this
tree, each in a worker process of the same form, the two in turns:

    nice python benchmarks/bench_sensors.py [--steps 2000] [--repeat 15] [--before /tmp/before]
"""
from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve()
sys.path.insert(0, str(HERE.parent))   # the sibling benchmark scripts

from bench_core import TreeWorker  # noqa: E402  (a worker on the tree before)

from arm_sim_ros.node.core import ArmSimCore  # noqa: E402
from arm_sim_ros.node.params.parameters import resolve_parameters  # noqa: E402
from arm_sim_ros.physics.scene import load_scene  # noqa: E402
from arm_sim_ros.physics.sensing.noise import Draws  # noqa: E402
from arm_sim_ros.physics.simulator import Simulator  # noqa: E402

STEP = 1e-3
FULL = {"seed": 7, "rate": 500.0, "position_resolution": [0.0015339807878856412] * 2,
        "position_noise": [1e-4, 1e-4], "velocity": "differences", "delay": 0.002}
RELEASE = load_scene("release").replace(step_size=STEP)
SERVO = load_scene("servo_hold")
SCENES = {   # label: scene
    "release, no sensors": RELEASE,
    "release, sensors: {} (model nothing)": RELEASE.replace(sensors={}),
    "release, full sensors (read, published)": RELEASE.replace(sensors=FULL),
    "servo_hold, no sensors": SERVO,
    "servo_hold, full sensors + command_delay": SERVO.replace(sensors=FULL, command_delay=1e-3),
}
NODE = {   # label: node parameters (one step a tick, publishing every step)
    "release, no sensors": {"scene": "release", "step_size": STEP, "publish_rate": 1000.0},
    "release, full sensors": {"scene": "release", "step_size": STEP, "publish_rate": 1000.0}
    | {f"sensors.{k}": v for k, v in FULL.items()},
    "servo_hold, no sensors": {"scene": "servo_hold", "publish_rate": 1000.0},
    "servo_hold, full sensors + command_delay": {"scene": "servo_hold", "publish_rate": 1000.0,
                                                 "command_delay": 1e-3}
    | {f"sensors.{k}": v for k, v in FULL.items()},
}
BEFORE_WORKER = r"""
import sys, time
import arm_sim_ros
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator
steps = int(sys.argv[1])
scene = load_scene("release").replace(step_size=1e-3)
print(arm_sim_ros.__file__, flush=True)
sim = Simulator(scene)
for _ in sys.stdin:
    sim.reset()
    start = time.perf_counter()
    for _ in range(steps):
        sim.step()
    stepped = time.perf_counter() - start
    sim.reset()
    start = time.perf_counter()
    sim.run(steps * 1e-3)
    ran = time.perf_counter() - start
    print(stepped / steps * 1e6, ran / steps * 1e6, flush=True)
"""


class Before(TreeWorker):
    """`release`'s step and run on the tree before sensors, in a worker process."""

    def __init__(self, tree: Path, steps: int):
        super().__init__(tree, BEFORE_WORKER, str(steps))


class Quiet:
    def info(self, text): pass
    def warning(self, text): pass
    def error(self, text): print(text, file=sys.stderr)


def timed(run, steps: int) -> float:
    start = time.perf_counter()
    run()
    return (time.perf_counter() - start) / steps * 1e6


def slots(steps: int):
    """(name, function -> µs per step or tick) of every row of this tree."""
    out = []
    for label, scene in SCENES.items():
        sim = Simulator(scene)

        def step(sim=sim):
            sim.reset()
            return timed(lambda: [sim.step() for _ in range(steps)], steps)

        def run(sim=sim):
            sim.reset()
            return timed(lambda: sim.run(steps * sim.step_size), steps)
        out += [(f"step  {label}", step), (f"run   {label}", run)]
    for label, parameters in NODE.items():
        core = ArmSimCore(resolve_parameters(parameters), Quiet(), wall_clock=lambda: 0.0,
                          start_stamp_ns=0)

        def tick(core=core):
            core.reset()
            return timed(lambda: [core.tick(0.0) for _ in range(steps)], steps)
        out.append((f"tick  {label}", tick))
    draws = Draws(7)
    out.append(("draw  one Gaussian draw (stream, joint, index)",
                lambda: timed(lambda: [draws.normal(0, 0, k) for k in range(steps)], steps)))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=15)
    parser.add_argument("--before", type=Path, metavar="DIR",
                        help="a checkout of the tree before sensors (main before the merge)")
    args = parser.parse_args()
    logging.disable(logging.WARNING)
    rows = slots(args.steps)
    # the tree before and this one each in a worker of the same form, in turns, so that
    # neither has the other's process (this one holds every row's simulator) or place
    workers = () if args.before is None else (Before(args.before, args.steps),
                                              Before(HERE.parents[1], args.steps))
    best = {name: float("inf") for name, _ in rows}
    for _ in range(2):                     # warm: compiled code, caches
        for name, measure in rows:
            measure()
        for worker in workers:
            worker.run()
    for worker in workers:
        worker.best = None
    try:
        for r in range(args.repeat):
            turn = rows[r % len(rows):] + rows[:r % len(rows)]
            for worker in workers[::1 if r % 2 else -1]:
                worker.run()
            for name, measure in turn:
                best[name] = min(best[name], measure())
    finally:
        for worker in workers:
            worker.close()
    print(f"µs per step (Simulator.step, Simulator.run) and per node tick (one step a tick, "
          f"publishing every step), h = {STEP:g} s; fastest of {args.repeat} rounds of "
          f"{args.steps}:")
    print(f"{'row':60s} {'µs':>8s} {'÷ no sensors':>13s}")
    for name, us in best.items():
        kind, _, label = name.partition("  ")
        scene = label.partition(",")[0]
        plain = best.get(f"{kind}  {scene}, no sensors", us)
        print(f"{name:60s} {us:8.2f} {us / plain:13.2f}")
    if workers:
        (step, run), (now_step, now_run) = (worker.best for worker in workers)
        print(f"\nthe tree before sensors ({args.before}) and this one, each in a worker, in "
              f"turns; release without sensors:")
        print(f"  step   before {step:6.2f} µs   now {now_step:6.2f} µs   now ÷ before "
              f"{now_step / step:5.2f}")
        print(f"  run    before {run:6.2f} µs   now {now_run:6.2f} µs   now ÷ before "
              f"{now_run / run:5.2f}")


if __name__ == "__main__":
    main()
