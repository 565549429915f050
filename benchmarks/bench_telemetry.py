"""Rerun logging overhead per simulated step at 1 kHz (h = 1 ms), file sink, on the paths
the node and `arm-sim run --rerun` take, each side by side with the same loop bare:

- node: ArmSimCore.tick() (no transport) at 100 Hz (10 steps per tick) and 1 kHz (1 step
  per tick); with telemetry the node hands the states of every recorder_link.RECORD_EVERY
  steps to RerunRecorder.step_batch() in one call;
- arm-sim run: cli.run_recorded() (Simulator.run, which also tracks the largest residual),
  bare and with the recorder the --rerun flag builds (step_batch every 1000 steps);
- per-step step(): Simulator.step() + RerunRecorder.step(sim) after each, the protocol a
  recorder without step_batch gets (against bare Simulator.step());
- per-sample rr.log: one rr.log per channel per step, energies from model's scalar
  functions, the drawing at the same 200 frames/s: what a straightforward sink costs.

What a recorder writes per step (issue 17): every readout on three timelines (sim_time,
ros_time, log_time), the 2D drawing and, for the URDF's arm, the 3D joints and torque arrows
at 200 frames/s, and on the node one story row per tick; all of it built in the sender
thread, so the simulation thread's cost is the copy of the states and a tuple per tick.

Columns: wall µs/step of the stepping loop (what the simulation feels), with its spread over
the rounds; CPU µs/step of the simulation thread; marginal CPU µs/step of the whole process
including the sender thread and rerun's encoder threads (runs of N and 2N steps, so the fixed
start/finish cost, shown apart, drops out; what the machine pays); bytes written per step.
The modes run round-robin, --repeat rounds, so each overhead is also taken within a round
(same machine load on both sides): median and range over the rounds.
A second table times the energy readouts alone: Simulator.energies per step vs the
vectorised readouts.energies per row of a batch (why readouts.energies exists).

    python benchmarks/bench_telemetry.py [--scene damped_release] [--seconds 30] [--repeat 7]

Files go to a temporary directory and are removed.
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import rerun as rr

from arm_sim_ros.tools import cli
from arm_sim_ros.physics import model
from arm_sim_ros.node import core as node_core
from arm_sim_ros.node.params import parameters
from arm_sim_ros.recording.rrd import blueprint, telemetry, writer
from arm_sim_ros.recording import readouts
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator

STEP = 0.001


class Clocks:
    """Wall and CPU clocks around the stepping loop, and around the whole recording."""

    def __enter__(self):
        self.process, self.outer = time.process_time(), time.perf_counter()
        self.loop_started()
        return self

    def loop_started(self):
        self.wall, self.thread = time.perf_counter(), time.thread_time()

    def loop_done(self):
        self.loop_wall = time.perf_counter() - self.wall
        self.loop_thread = time.thread_time() - self.thread
        self.finish_started = time.perf_counter()

    def __exit__(self, *exc):
        self.total_process = time.process_time() - self.process
        # start-up (before the loop) + finish (after it)
        self.fixed = (self.wall - self.outer) + (time.perf_counter() - self.finish_started)


def step_loop(scene, steps, path, recorded):
    """Simulator.step() in a loop, with RerunRecorder.step(sim) after each if `recorded`."""
    sim = Simulator(scene)
    advance = sim.step
    with Clocks() as clocks:
        recorder = telemetry.make_recorder(scene, path=str(path)) if recorded else None
        if recorder is None:
            clocks.loop_started()
            for _ in range(steps):
                advance()
            clocks.loop_done()
            return clocks
        recorder.start(sim)
        record = recorder.step
        clocks.loop_started()
        for _ in range(steps):
            advance()
            record(sim)
        clocks.loop_done()
        recorder.finish(sim)
    return clocks


class Quiet:
    def __getattr__(self, level):
        return lambda text: None


def node_loop(scene, steps, path, recorded, rate):
    """ArmSimCore.tick() as the node's timer calls it (no transport; ticks back to back)."""
    overrides = {"scene": scene.name, "step_size": STEP, "publish_rate": rate}
    if recorded:
        overrides["rerun_path"] = str(path)
    with Clocks() as clocks:
        core = node_core.ArmSimCore(parameters.resolve_parameters(overrides), Quiet(),
                                    wall_clock=lambda: 0.0, start_stamp_ns=0)
        tick = core.tick
        clocks.loop_started()
        for _ in range(steps // core.config.steps_per_tick):
            tick(0.0)
        clocks.loop_done()
        core.finish()
    return clocks


def run_loop(scene, steps, path, recorded):
    """`arm-sim run [--rerun PATH]`: cli.run_recorded with the recorder --rerun builds."""
    sim = Simulator(scene)
    with Clocks() as clocks:
        recorders = [telemetry.make_recorder(path=str(path))] if recorded else []
        for recorder in recorders:
            recorder.start(sim)
        clocks.loop_started()
        cli.run_recorded(sim, steps * STEP, recorders)
        clocks.loop_done()
        for recorder in recorders:
            recorder.finish(sim)
    return clocks


def per_sample(scene, steps, path):
    """One rr.log per channel per step, as a first version of the sink would do it."""
    sim = Simulator(scene)
    arm, gravity = sim.arm, scene.gravity
    every = round(writer.FRAME_PERIOD / scene.step_size)
    dissipated = (4 + len(sim.extra) + sim.channels.index("dissipated")
                  if "dissipated" in sim.channels else None)
    with Clocks() as clocks:
        stream = rr.RecordingStream("arm_sim_bench")
        stream.save(str(path))
        clocks.loop_started()
        for k in range(steps):
            sim.step()
            y = sim.state
            q, qd = (y[0], y[1]), (y[2], y[3])
            kinetic = model.kinetic_energy(arm, q, qd)
            potential = model.potential_energy(arm, q, gravity)
            stream.set_time(blueprint.TIMELINE, duration=sim.time)
            stream.log("energy/kinetic", rr.Scalars(kinetic))
            stream.log("energy/potential", rr.Scalars(potential))
            stream.log("energy/total", rr.Scalars(kinetic + potential))
            if dissipated is not None:
                stream.log("books/loss/dissipated", rr.Scalars(y[dissipated]))
            stream.log("energy/balance_residual", rr.Scalars(sim.residual()))
            stream.log("joints/angle", rr.Scalars(q))
            stream.log("joints/velocity", rr.Scalars(qd))
            if k % every == 0:
                base, elbow, tip = [(x, -yy) for x, yy in model.link_points(arm, q)]
                stream.log("arm/links", rr.LineStrips2D([[base, elbow], [elbow, tip]]))
                stream.log("arm/joints", rr.Points2D([base, elbow, tip]))
        clocks.loop_done()
        stream.flush()
        stream.disconnect()
    return clocks


# (name, function(scene, steps, path), its bar: the same loop without telemetry, or None)
def modes():
    return [
        ("node tick 100 Hz, bare", lambda *a: node_loop(*a, False, 100.0), None),
        ("node tick 100 Hz + telemetry", lambda *a: node_loop(*a, True, 100.0),
         "node tick 100 Hz, bare"),
        ("node tick 1 kHz, bare", lambda *a: node_loop(*a, False, 1000.0), None),
        ("node tick 1 kHz + telemetry", lambda *a: node_loop(*a, True, 1000.0),
         "node tick 1 kHz, bare"),
        ("arm-sim run, bare", lambda *a: run_loop(*a, False), None),
        ("arm-sim run --rerun", lambda *a: run_loop(*a, True), "arm-sim run, bare"),
        ("Simulator.step(), bare", lambda *a: step_loop(*a, False), None),
        ("step() + recorder.step(sim)", lambda *a: step_loop(*a, True),
         "Simulator.step(), bare"),
    ]


def energies_scalar(states, sim):
    start = time.perf_counter()
    energy = sim.energy
    for y in states:
        energy(y)
    return time.perf_counter() - start


def energies_vectorised(states, sim):
    start = time.perf_counter()
    kinetic, stored = readouts.energies(readouts.Snapshot(sim), np.array(states))
    kinetic + sum(stored.values())
    return time.perf_counter() - start


class Runs:
    """One mode's clocks over the rounds, at `steps` and at 2 x steps."""

    def __init__(self, steps):
        self.steps, self.short, self.long, self.size = steps, [], [], None

    def per_step(self, clock):
        """µs per step of the longer runs, one per round."""
        return [getattr(c, clock) / (2 * self.steps) * 1e6 for c in self.long]

    def process(self):
        """Marginal process CPU µs per step: the longer run minus the shorter, per extra
        step, so the fixed start/finish cost drops out."""
        return (min(c.total_process for c in self.long)
                - min(c.total_process for c in self.short)) / self.steps * 1e6


def measure(table, scene, steps, repeat, tmp):
    """Every mode of `table` at steps and 2 x steps, round-robin: {name: Runs}."""
    runs = {name: Runs(steps) for name, _, _ in table}
    path = Path(tmp) / "bench.rrd"
    for _ in range(repeat):
        for name, run, _ in table:
            runs[name].short.append(run(scene, steps, path))
            runs[name].long.append(run(scene, 2 * steps, path))
            if path.exists():
                runs[name].size = path.stat().st_size / (2 * steps)
                path.unlink()
    return runs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="damped_release")
    parser.add_argument("--seconds", type=float, default=30.0,
                        help="simulated seconds of the shorter run (the longer is twice that)")
    parser.add_argument("--per-sample-seconds", type=float, default=1.0,
                        help="simulated seconds for the (slow) per-sample sink")
    parser.add_argument("--repeat", type=int, default=7, help="rounds")
    args = parser.parse_args()
    scene = load_scene(args.scene).replace(step_size=STEP)
    steps = round(args.seconds / STEP)
    table = modes()
    with tempfile.TemporaryDirectory() as tmp:
        runs = measure(table, scene, steps, args.repeat, tmp)
        slow = ("per-sample rr.log", per_sample, "Simulator.step(), bare")
        runs |= measure([slow], scene, round(args.per_sample_seconds / STEP),
                        max(1, args.repeat // 3), tmp)
        table.append(slow)

    print(f"Rerun file-sink overhead, scene {scene.name}, h = {STEP * 1e3:g} ms (1 kHz), "
          f"{args.repeat} rounds; µs per simulated step, best and range over the rounds")
    print(f"{'mode':30s} {'steps':>6s} {'loop wall':>10s} {'(range)':>13s} {'sim thread':>11s} "
          f"{'process CPU':>12s} {'start+finish':>13s} {'bytes/step':>11s}")
    for name, _, _ in table:
        r = runs[name]
        wall = r.per_step("loop_wall")
        size = "-" if r.size is None else f"{r.size:.0f}"
        print(f"{name:30s} {2 * r.steps:6d} {min(wall):10.2f} "
              f"{f'{min(wall):.2f}–{max(wall):.2f}':>13s} {min(r.per_step('loop_thread')):11.2f} "
              f"{r.process():12.2f} {min(c.fixed for c in r.long) * 1e3:10.1f} ms {size:>11s}")
    print()
    print(f"{'overhead vs the same loop bare':30s} {'loop wall':>10s} {'per round: median':>18s} "
          f"{'(range)':>15s} {'sim thread':>11s} {'process CPU':>12s}")
    for name, _, bar in table:
        if bar is None:
            continue
        r, b = runs[name], runs[bar]
        wall, base = r.per_step("loop_wall"), b.per_step("loop_wall")
        rounds = [100 * (w / v - 1) for w, v in zip(wall, base)]   # same round, same load
        thread = min(r.per_step("loop_thread")) / min(b.per_step("loop_thread"))
        print(f"{name:30s} {100 * (min(wall) / min(base) - 1):9.1f}% "
              f"{statistics.median(rounds):17.1f}% "
              f"{f'{min(rounds):.1f} to {max(rounds):.1f}%':>15s} {100 * (thread - 1):10.1f}% "
              f"{100 * (r.process() / b.process() - 1):11.1f}%")

    sim = Simulator(scene)
    states = []
    for _ in range(steps):
        sim.step()
        states.append(sim.state)
    scalar = min(energies_scalar(states, sim) for _ in range(args.repeat)) / steps
    vector = min(energies_vectorised(states, sim) for _ in range(args.repeat)) / steps
    print()
    print(f"{'energy readouts (T, V, E) of one step':44s} {'µs/step':>9s}")
    print(f"{'Simulator.energy per step':44s} {scalar * 1e6:9.3f}")
    print(f"{'readouts.energies over a batch, per row':44s} {vector * 1e6:9.3f}")


if __name__ == "__main__":
    main()
