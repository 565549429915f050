"""Many samples of one scene (physics.batch.run_scenes, what `arm-sim sweep` runs) against
MuJoCo's rollout of the same arm, per core; what sensors cost a sample; and switching
samples against Simulator.run of the same scenes one at a time.

Rows (samples per second, and per core: divided by the threads used), wall time:

  release     --samples Monte Carlo samples of `release`, --seconds at h = --step, estimate
              off: initial positions uniform +-0.5 rad about the scene's, link masses
              uniform x [0.8, 1.2]; run_scenes on one thread and on every core, and on one
              thread handing every trajectory to an observer (as a sweep's figures take
              them; the observer itself does nothing).
  mujoco      mujoco.rollout (RK4, tools/accuracy/mujoco_peer.py) of the first
              --mujoco-samples of the same samples, a model per sample (its masses; built
              before the clock starts), on one thread and on every core.
  sensors     the first --sensor-samples samples with the sensors of sensors.md's contract
              (seed per sample, 500 Hz, 4096 counts, noise 1e-4 rad, differenced velocity,
              delay 2 ms), against the same samples without sensors, one thread.
  stick_slip  --switching-samples samples of `stick_slip` (initial positions varied, estimate
              off, 6 s at its h = 10 ms): run_scenes on one thread against Simulator(scene)
              .run one scene at a time, after a run of them all (every mode they meet
              compiled or loaded), interleaved, the faster of two each.

Every run_scenes row builds its simulators inside the clock. Three samples of each row are
checked against their own Simulator.run, bit for bit (the line under the table).

    nice python benchmarks/bench_sweep.py                  # the full run (minutes)
    nice python benchmarks/bench_sweep.py --quick          # small settings, a minute
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from arm_sim_ros.physics.batch import run_scenes  # noqa: E402
from arm_sim_ros.physics.scene import load_scene  # noqa: E402
from arm_sim_ros.physics.simulator import Simulator  # noqa: E402
from arm_sim_ros.tools.accuracy import mujoco_peer  # noqa: E402

SENSORS = {"rate": 500.0, "position_resolution": [2 * np.pi / 4096] * 2,
           "position_noise": [1e-4, 1e-4], "velocity": "differences", "delay": 0.002}
QUICK = {"samples": 400, "seconds": 2.0, "mujoco_samples": 20, "sensor_samples": 200,
         "switching_samples": 40}


def off(scene):
    return scene.replace(estimate="off", tolerance=0.0)


def release_samples(count: int, step: float, seed: int = 46) -> list:
    """The Monte Carlo samples: positions about the scene's, masses x [0.8, 1.2]."""
    scene = off(load_scene("release")).replace(step_size=step)
    rng = np.random.default_rng(seed)
    q = np.asarray(scene.initial_positions) + rng.uniform(-0.5, 0.5, (count, 2))
    masses = np.asarray(scene.link_masses) * rng.uniform(0.8, 1.2, (count, 2))
    return [scene.replace(initial_positions=tuple(map(float, p)),
                          link_masses=tuple(map(float, m))) for p, m in zip(q, masses)]


def timed(run) -> float:
    start = time.perf_counter()
    run()
    return time.perf_counter() - start


def ours(scenes, seconds: float, threads: int, observe=None) -> float:
    """Samples per second of run_scenes."""
    return len(scenes) / timed(lambda: run_scenes(scenes, seconds, threads=threads,
                                                  observe=observe))


def mujoco_rate(scenes, seconds: float, threads: int) -> float:
    """Samples per second of mujoco.rollout, a model per sample."""
    import mujoco
    from mujoco import rollout

    models = [mujoco_peer.mujoco_model(scene, "RK4")[0] for scene in scenes]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    initial = np.zeros((len(scenes), mujoco.mj_stateSize(models[0], spec)))
    for i, (model, scene) in enumerate(zip(models, scenes)):
        data = mujoco_peer.mujoco_data(model, scene, [])
        mujoco.mj_getState(model, data, initial[i], spec)
    datas = [mujoco.MjData(models[0]) for _ in range(threads)]
    steps = round(seconds / scenes[0].step_size)
    with rollout.Rollout(nthread=threads) as pool:
        pool.rollout(models[:1], datas, initial[:1], nstep=10)       # warm
        elapsed = timed(lambda: pool.rollout(models, datas, initial, nstep=steps))
    return len(scenes) / elapsed


def one_at_a_time(scenes, seconds: float) -> float:
    """Samples per second of Simulator(scene).run, one scene after another."""
    return len(scenes) / timed(lambda: [Simulator(scene).run(seconds) for scene in scenes])


def checked(scenes, seconds: float) -> str:
    """Three samples' outcomes against their own Simulator.run, bit for bit."""
    picked = [scenes[0], scenes[len(scenes) // 2], scenes[-1]]
    outcomes = run_scenes(picked, seconds)
    for scene, outcome in zip(picked, outcomes):
        sim = Simulator(scene)
        largest = sim.run(seconds)
        if (tuple(outcome.q) + tuple(outcome.qd), outcome.max_abs_residual) != \
                (tuple(sim.state[:4]), largest):
            return f"differs from Simulator.run: {scene.name} {outcome}"
    return "equal"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=10_000)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--step", type=float, default=1e-3)
    parser.add_argument("--mujoco-samples", type=int, default=200)
    parser.add_argument("--sensor-samples", type=int, default=1000)
    parser.add_argument("--switching-samples", type=int, default=200)
    parser.add_argument("--quick", action="store_true", help=f"small settings: {QUICK}")
    args = parser.parse_args()
    if args.quick:
        vars(args).update(QUICK)
    cores = os.cpu_count() or 1
    seconds = args.seconds
    samples = release_samples(args.samples, args.step)
    run_scenes(samples[:2], 0.01, threads=cores)      # compiled, or loaded from the cache
    started = time.perf_counter()
    rows = []                                          # (label, samples/s, threads)
    for threads in sorted({1, cores}):
        rows.append((f"release, run_scenes, {threads} thread(s)",
                     ours(samples, seconds, threads), threads))
    rows.append(("release, run_scenes + trajectories, 1 thread",
                 ours(samples, seconds, 1, lambda *chunk: None), 1))
    few = samples[:args.mujoco_samples]
    for threads in sorted({1, cores}):
        rows.append((f"release, mujoco.rollout, {threads} thread(s)",
                     mujoco_rate(few, seconds, threads), threads))
    plain = samples[:args.sensor_samples]
    sensed = [scene.replace(sensors=SENSORS | {"seed": i}) for i, scene in enumerate(plain)]
    run_scenes(sensed[:2], 0.01)
    rows.append(("release, no sensors, 1 thread", ours(plain, seconds, 1), 1))
    rows.append(("release, sensors, 1 thread", ours(sensed, seconds, 1), 1))
    stick = off(load_scene("stick_slip"))
    rng = np.random.default_rng(7)
    switching = [stick.replace(initial_positions=tuple(map(float, p)))
                 for p in rng.uniform(-0.5, 0.5, (args.switching_samples, 2))]
    run_scenes(switching, 6.0)       # every mode these samples meet compiled (or loaded)
    best = [0.0, 0.0]
    for _ in range(2):               # interleaved, the faster of two each
        best = [max(best[0], ours(switching, 6.0, 1)),
                max(best[1], one_at_a_time(switching, 6.0))]
    rows.append(("stick_slip, run_scenes, 1 thread", best[0], 1))
    rows.append(("stick_slip, Simulator.run one at a time", best[1], 1))
    rate = dict((label, value) for label, value, _ in rows)
    print(f"{args.samples} samples of release, {seconds:g} s at h = {args.step:g} s "
          f"(mujoco: the first {len(few)}; sensors: the first {len(plain)}; "
          f"{len(switching)} of stick_slip, 6 s); {cores} cores")
    print(f"{'row':48s} {'samples/s':>10s} {'per core':>10s}")
    for label, value, threads in rows:
        print(f"{label:48s} {value:10.2f} {value / threads:10.2f}")
    for threads in sorted({1, cores}):
        ratio = (rate[f"release, run_scenes, {threads} thread(s)"]
                 / rate[f"release, mujoco.rollout, {threads} thread(s)"])
        print(f"{'' if threads > 1 else chr(10)}ours / mujoco per core, {threads} thread(s) "
              f"each: {ratio:.1f}x")
    print(f"a sample with sensors / without: "
          f"{rate['release, no sensors, 1 thread'] / rate['release, sensors, 1 thread']:.2f}x")
    print(f"stick_slip: run_scenes / one at a time: "
          f"{rate['stick_slip, run_scenes, 1 thread'] / rate['stick_slip, Simulator.run one at a time']:.2f}x")
    print(f"spot checks against Simulator.run: release {checked(samples, seconds)}, sensors "
          f"{checked(sensed, seconds)}, stick_slip {checked(switching, 6.0)}")
    print(f"({time.perf_counter() - started:.0f} s)")


if __name__ == "__main__":
    main()
