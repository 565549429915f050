"""Our arm side by side with the same arm in MuJoCo, timed in the same run.

The MuJoCo model is built from the scene by arm_sim_ros.tools.accuracy.mujoco_peer (hinges about z,
gravity along -y, explicit inertials, no contacts), as `arm-sim accuracy` builds it. Built
this way MuJoCo's RK4 reproduces ours to ~1e-15. Errors are the max state error against the DOP853 reference (study.reference)
at every publish time; times are the fastest of --repeat runs; ratios are against ours.

    pip install .[bench]
    python benchmarks/bench_peers.py [--scene release] [--duration 2] [--arms 1000000]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))   # the sibling benchmark scripts

from bench_core import fastest  # noqa: E402  (the benchmarks' best-of-repeats timing)

from arm_sim_ros.physics.batch import Batch  # noqa: E402
from arm_sim_ros.physics.scene import load_scene  # noqa: E402
from arm_sim_ros.physics.simulator import Simulator  # noqa: E402
from arm_sim_ros.tools.accuracy.command import reference, sample_times  # noqa: E402
from arm_sim_ros.tools.accuracy.mujoco_peer import mujoco_data, mujoco_model, reset  # noqa: E402


def ours_single(scene, steps: int):
    sim = Simulator(scene)
    states = [sim.state[:4]]

    def run():
        sim.reset()
        states[1:] = []
        for _ in range(steps):
            sim.step()
            states.append(sim.state[:4])
    return run, states


def mujoco_single(scene, integrator: str, steps: int):
    import mujoco

    model, ctrl = mujoco_model(scene, integrator)
    data = mujoco_data(model, scene, ctrl)
    states = []

    def run():
        reset(model, data, scene, ctrl)
        states[:] = [(*data.qpos, *data.qvel)]
        for _ in range(steps):
            mujoco.mj_step(model, data)
            states.append((*data.qpos, *data.qvel))
    return run, states


def max_error(states, ref, every: int) -> float:
    return max(abs(a - b) for s, r in zip(states[::every], ref) for a, b in zip(s, r[:4]))


def single_arm_table(scene, duration: float, repeat: int) -> list[str]:
    steps = scene.steps_for(duration)
    times = sample_times(scene, duration, scene.step_size)
    ref = reference(scene, times)
    # tolerance 0: the scheme alone, so that ours and MuJoCo's take the same steps
    rows = [(f"ours {name} (Simulator.step)",
             *ours_single(scene.replace(integrator=name, tolerance=0.0), steps))
            for name in ("rk4", "semi_implicit_euler", "dopri5")]
    for integrator in ("RK4", "implicitfast", "Euler"):
        rows.append((f"mujoco {integrator} (mj_step)", *mujoco_single(scene, integrator, steps)))
    results = []
    for label, run, states in rows:
        seconds = fastest(run, repeat)
        results.append((label, seconds / steps * 1e6, max_error(states, ref, 1)))
    ours_us = results[0][1]
    lines = [f"single arm: scene {scene.name}, {steps} steps of {scene.step_size:g} s, fastest of "
             f"{repeat}; error = max |state - DOP853 reference| at every step",
             f"{'method':<42} {'us/step':>8} {'time / ours rk4':>15} {'max |state err|':>15}",
             "-" * 83]
    lines += [f"{label:<42} {us:>8.2f} {us / ours_us:>15.2f} {err:>15.3e}"
              for label, us, err in results]
    # Same schemes, same arm: MuJoCo's RK4 is our rk4, its Euler is our semi-implicit Euler
    # (without damping: MuJoCo's Euler integrates joint damping implicitly).
    for ours, theirs, label in ((0, 3, "ours rk4 - mujoco RK4"),
                                (1, 5, "ours semi_implicit_euler - mujoco Euler")):
        gap = max(abs(a - b) for s, t in zip(rows[ours][2], rows[theirs][2]) for a, b in zip(s, t))
        lines.append(f"max |{label}| over the run: {gap:.1e}")
    return lines


def batch_table(scene, arms: int, mujoco_arms: int, steps: int, repeat: int) -> list[str]:
    import mujoco
    from mujoco import rollout

    rng = np.random.default_rng(0)
    positions = np.asarray(scene.initial_positions) + rng.uniform(-0.5, 0.5, (arms, 2))
    batch = Batch(scene, positions)

    def ours():
        batch.reset()
        batch.run(steps)
    ours_s = fastest(ours, repeat)

    model, ctrl = mujoco_model(scene, "RK4")
    data = mujoco_data(model, scene, ctrl)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    initial = np.zeros((mujoco_arms, mujoco.mj_stateSize(model, spec)))
    mujoco.mj_getState(model, data, initial[0], spec)
    initial[:] = initial[0]
    # FULLPHYSICS = time, qpos, qvel, ...: the same spread of initial poses as ours.
    initial[:, 1:3] = positions[:mujoco_arms]
    rollout.rollout(model, data, initial[:2], nstep=steps)          # warm up
    mujoco_s = fastest(lambda: rollout.rollout(model, data, initial, nstep=steps), repeat)
    state, _ = rollout.rollout(model, data, initial, nstep=steps)
    batch.reset()
    batch.run(steps)
    ours_final = np.stack(batch.state[:4], axis=1)[:mujoco_arms]
    gap = float(np.max(np.abs(state[:, -1, 1:5] - ours_final)))

    ours_rate = arms * steps / ours_s
    mujoco_rate = mujoco_arms * steps / mujoco_s
    return [f"batch: {steps} RK4 steps, 1 thread each (this machine gives one process about one "
            "core)",
            f"{'method':<34} {'arms':>9} {'M arm-steps/s':>13} {'ours / it':>9}",
            "-" * 68,
            f"{'ours Batch (numpy, chunked)':<34} {arms:>9} {ours_rate / 1e6:>13.2f} {1.0:>9.2f}",
            f"{'mujoco.rollout RK4':<34} {mujoco_arms:>9} {mujoco_rate / 1e6:>13.2f} "
            f"{ours_rate / mujoco_rate:>9.2f}",
            f"max |ours - mujoco.rollout| after {steps} steps: {gap:.1e}"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="release", choices=["release", "damped_release",
                                                               "downward_equilibrium"])
    parser.add_argument("--duration", type=float, default=2.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--arms", type=int, default=1_000_000)
    parser.add_argument("--mujoco-arms", type=int, default=20_000)
    parser.add_argument("--batch-steps", type=int, default=10)
    args = parser.parse_args()
    scene = load_scene(args.scene)
    print("\n".join(single_arm_table(scene, args.duration, args.repeat)))
    print()
    print("\n".join(batch_table(scene, args.arms, args.mujoco_arms, args.batch_steps,
                                args.repeat)))


if __name__ == "__main__":
    main()
