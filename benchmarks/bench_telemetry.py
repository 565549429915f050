"""Rerun logging overhead per simulated step at 1 kHz (h = 1 ms), file sink, in one run:

- bare: Simulator.step() alone, the bar;
- batched: step() + RerunRecorder.step(), i.e. the state tuple appended; batches go to
  the sender thread (numpy for energies/torques/drawing, one send_columns per entity);
- per-sample: step() + one rr.log per channel per step, energies from model's scalar
  functions, the drawing at the same 200 frames/s: what a straightforward sink costs.

Columns: wall µs/step of the stepping loop (what the simulation feels), CPU µs/step of
the simulation thread, marginal CPU µs/step of the whole process including the sender
thread and rerun's encoder (runs of N and 2N steps; what the machine pays), and the
per-recording start + finish wall time.
A second table times the energy readouts alone: model's scalar functions per step vs
the vectorised helper per row of a batch (why telemetry.energies exists).

    python benchmarks/bench_telemetry.py [--scene damped_release] [--seconds 30] [--repeat 5]

Each figure is the best of --repeat runs, clock by clock: the machine is shared, the
minimum is the least disturbed. Files go to a temporary directory and are removed.
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import rerun as rr

from arm_sim_ros import model, telemetry
from arm_sim_ros.scene import load_scene
from arm_sim_ros.simulator import Simulator

STEP = 0.001


class Clocks:
    """Wall and CPU clocks around the stepping loop, and around the whole recording."""

    def __enter__(self):
        self.wall, self.thread, self.process = (time.perf_counter(), time.thread_time(),
                                                time.process_time())
        self.outer = self.wall
        return self

    def loop_done(self):
        self.loop_wall = time.perf_counter() - self.wall
        self.loop_thread = time.thread_time() - self.thread

    def __exit__(self, *exc):
        self.total_process = time.process_time() - self.process
        self.total_wall = time.perf_counter() - self.outer


def bare(scene, steps, _path):
    sim = Simulator(scene)
    advance = sim.step
    with Clocks() as clocks:
        for _ in range(steps):
            advance()
        clocks.loop_done()
    clocks.fixed = 0.0
    return clocks


def batched(scene, steps, path):
    sim = Simulator(scene)
    with Clocks() as clocks:
        recorder = telemetry.make_recorder(scene, path=str(path))
        recorder.start(sim)
        advance, record = sim.step, recorder.step
        clocks.wall, clocks.thread = time.perf_counter(), time.thread_time()
        for _ in range(steps):
            advance()
            record(sim)
        clocks.loop_done()
        finish_start = time.perf_counter()
        recorder.finish(sim)
        clocks.fixed = (clocks.wall - clocks.outer) + (time.perf_counter() - finish_start)
    return clocks


def per_sample(scene, steps, path):
    """One rr.log per channel per step, as a first version of the sink would do it."""
    sim = Simulator(scene)
    arm, gravity = sim.arm, scene.gravity
    every = round(telemetry.FRAME_PERIOD / scene.step_size)
    dissipated = 4 + sim.channels.index("dissipated") if "dissipated" in sim.channels else None
    with Clocks() as clocks:
        stream = rr.RecordingStream("arm_sim_bench")
        stream.save(str(path))
        clocks.wall, clocks.thread = time.perf_counter(), time.thread_time()
        for k in range(steps):
            sim.step()
            y = sim.state
            q, qd = (y[0], y[1]), (y[2], y[3])
            kinetic = model.kinetic_energy(arm, q, qd)
            potential = model.potential_energy(arm, q, gravity)
            stream.set_time(telemetry.TIMELINE, duration=sim.time)
            stream.log("energy/kinetic", rr.Scalars(kinetic))
            stream.log("energy/potential", rr.Scalars(potential))
            stream.log("energy/total", rr.Scalars(kinetic + potential))
            if dissipated is not None:
                stream.log("energy/dissipated", rr.Scalars(y[dissipated]))
            stream.log("energy/balance_residual", rr.Scalars(sim.residual()))
            stream.log("joints/angle", rr.Scalars(q))
            stream.log("joints/velocity", rr.Scalars(qd))
            if k % every == 0:
                base, elbow, tip = [(x, -yy) for x, yy in model.link_points(arm, q)]
                stream.log("arm/links", rr.LineStrips2D([[base, elbow], [elbow, tip]]))
                stream.log("arm/joints", rr.Points2D([base, elbow, tip]))
        clocks.loop_done()
        finish_start = time.perf_counter()
        stream.flush()
        stream.disconnect()
        clocks.fixed = (clocks.wall - clocks.outer) + (time.perf_counter() - finish_start)
    return clocks


def energies_scalar(states, arm, gravity):
    start = time.perf_counter()
    for y in states:
        q, qd = (y[0], y[1]), (y[2], y[3])
        model.kinetic_energy(arm, q, qd) + model.potential_energy(arm, q, gravity)
    return time.perf_counter() - start


def energies_vectorised(states, arm, gravity):
    start = time.perf_counter()
    array = np.array(states)
    kinetic, potential = telemetry.energies(arm, gravity, *array[:, :4].T)
    kinetic + potential
    return time.perf_counter() - start


def best(run, repeat, *args):
    """Each clock's least disturbed reading over `repeat` runs."""
    runs = [run(*args) for _ in range(repeat)]
    fastest = runs[0]
    for name in ("loop_wall", "loop_thread", "total_process", "fixed"):
        setattr(fastest, name, min(getattr(c, name) for c in runs))
    return fastest


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="damped_release")
    parser.add_argument("--seconds", type=float, default=30.0,
                        help="simulated seconds of the shorter run (the longer is twice that)")
    parser.add_argument("--per-sample-seconds", type=float, default=1.0,
                        help="simulated seconds for the (slow) per-sample sink")
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    scene = load_scene(args.scene).replace(step_size=STEP)
    steps, slow_steps = round(args.seconds / STEP), round(args.per_sample_seconds / STEP)

    with tempfile.TemporaryDirectory() as tmp:
        rows = []
        for name, run, n in (("bare Simulator.step()", bare, steps),
                             ("batched send_columns (telemetry)", batched, steps),
                             ("per-sample rr.log", per_sample, slow_steps)):
            path = Path(tmp) / f"{run.__name__}.rrd"
            short = best(run, args.repeat, scene, n, path)
            long = best(run, args.repeat, scene, 2 * n, path)
            size = path.stat().st_size / (2 * n) if path.exists() else None
            # Marginal process CPU: the run twice as long minus the run, per extra step,
            # so the fixed start/finish cost (shown apart) drops out.
            rows.append((name, 2 * n, long.loop_wall / (2 * n), long.loop_thread / (2 * n),
                         (long.total_process - short.total_process) / n, long.fixed, size))
    _, _, base_wall, base_thread, base_process, _, _ = rows[0]
    print(f"Rerun file-sink overhead, scene {scene.name}, h = {STEP * 1e3:g} ms (1 kHz), "
          f"best of {args.repeat}; µs per simulated step")
    print(f"{'mode':34s} {'steps':>6s} {'loop wall':>10s} {'sim thread':>11s} "
          f"{'process CPU':>12s} {'start+finish':>13s} {'bytes/step':>11s}")
    for name, n, wall, thread, process, fixed, size in rows:
        print(f"{name:34s} {n:6d} {wall * 1e6:10.2f} {thread * 1e6:11.2f} {process * 1e6:12.2f} "
              f"{fixed * 1e3:10.1f} ms {'-' if size is None else f'{size:.0f}':>11s}")
    print(f"{'overhead vs bare':34s} {'':6s} {'loop wall':>10s} {'sim thread':>11s} "
          f"{'process CPU':>12s}")
    for name, _, wall, thread, process, _, _ in rows[1:]:
        print(f"{name:34s} {'':6s} {100 * (wall / base_wall - 1):9.1f}% "
              f"{100 * (thread / base_thread - 1):10.1f}% "
              f"{100 * (process / base_process - 1):11.1f}%")

    sim = Simulator(scene)
    states = []
    for _ in range(steps):
        sim.step()
        states.append(sim.state)
    scalar = min(energies_scalar(states, sim.arm, scene.gravity)
                 for _ in range(args.repeat)) / steps
    vector = min(energies_vectorised(states, sim.arm, scene.gravity)
                 for _ in range(args.repeat)) / steps
    print()
    print(f"{'energy readouts (T, V, E) of one step':44s} {'µs/step':>9s}")
    print(f"{'model.kinetic/potential_energy per step':44s} {scalar * 1e6:9.3f}")
    print(f"{'telemetry.energies over a batch, per row':44s} {vector * 1e6:9.3f}")


if __name__ == "__main__":
    main()
