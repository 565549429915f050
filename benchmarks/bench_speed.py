"""Where the time goes: Simulator.step (the node's path) and Simulator.run per preset, pure
Python against compiled (extra `fast`), beside MuJoCo 4.0's RK4 on the same scene (mj_step
called from Python) and the compiled limit; a windings scene naming no integrator against
the plain arm; Batch against mujoco.rollout; and the windings integrated exactly
(exponential_rk4) against rk4's sub-steps and MuJoCo's first-order dcmotor at equal step;
and what a scene's first compile costs (first_compile: a new process each, an empty cache).

Simulator.step table: µs per step at h = 1 ms, python and compiled (one compiled call per
step: compiled/runs.py), estimate global (default tolerance) and off, mj_step and the
limit (the bare loop's cost per step), interleaved.

Presets table (µs per simulated second, and steps per second):
  python     Simulator.run with ARM_SIM_COMPILED=0, default tolerance
  compiled   Simulator.run on the compiled path (compiled/), the same steps bit for bit:
             runs of plain steps in one call; switching scenes (events.py) too, each run
             of steps in one mode where nothing can switch (switch_run.py), the others
             from Python
  off        compiled, estimate off (no shadow, no checks; tolerance 0)
  mujoco     mj_step in a Python loop, RK4, the scene built by tools/mujoco_peer (only where
             it models the same physics: no soft friction or limits, no controller model)
  limit      the bare compiled RK4 loop on the same right-hand side (the planned sub-steps,
             no accuracy checks, no residual, no switching: friction's mode-free form)
  sub/step   the RK4 sub-steps the run takes per step: the plan's, and the tolerance's where
             it splits steps to meet it (release: where the elbow whips)
  of same    compiled against the limit taking as many sub-steps: what the error books,
             the energy books and the switches cost beyond the steps themselves
  off of     off against the limit at the planned sub-steps (which off takes)
Each keeps the fastest of --repeat runs of --seconds simulated seconds after one warm-up run
(`first`: that run, compiling what it meets or loading it from the cache), a row's columns
interleaved (each run once a round, so a slow spell falls on all of them), timed in CPU
seconds of this process (the machine is shared: wall time would count the others' work),
Batch in CPU seconds and in wall seconds (its threads share the work).

    pip install -e '.[bench,fast]'
    nice python benchmarks/bench_speed.py [--seconds 2] [--repeat 3] [--arms 20000]
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from arm_sim_ros.physics.compiled import build as compiled  # noqa: E402
from arm_sim_ros.physics.batch import Batch  # noqa: E402
from arm_sim_ros.physics.dynamics import build_dynamics  # noqa: E402
from arm_sim_ros.physics.scene import load_scene, preset_names  # noqa: E402
from arm_sim_ros.physics.simulator import Simulator  # noqa: E402
from arm_sim_ros.tools.accuracy import mujoco_peer  # noqa: E402


def fastest(run, repeat: int, clock=time.process_time) -> float:
    """The least time of `repeat` runs: CPU time of this process (single-threaded work: a
    machine shared with other jobs preempts it, which wall time would count), or wall
    time where threads share the work (clock=time.perf_counter)."""
    best = math.inf
    for _ in range(repeat):
        start = clock()
        run()
        best = min(best, clock() - start)
    return best


def simulator(scene, fast: bool) -> Simulator:
    os.environ["ARM_SIM_COMPILED"] = "1" if fast else "0"
    try:
        return Simulator(scene)
    finally:
        os.environ.pop("ARM_SIM_COMPILED")


def prepared_run(scene, seconds: float, fast: bool):
    """(a run of `seconds` simulated from the scene's start, path, first-call seconds)."""
    sim = simulator(scene, fast)
    start = time.perf_counter()
    sim.run(seconds)       # compiles (or loads from the cache) every mode the run meets
    first = time.perf_counter() - start

    def run():
        sim.reset()
        sim.run(seconds)
    return run, sim.path, first


def time_run(scene, seconds: float, repeat: int, fast: bool):
    """(CPU seconds for `seconds` simulated, path, first-call seconds)."""
    run, path, first = prepared_run(scene, seconds, fast)
    return fastest(run, repeat), path, first


def interleaved(runs: dict, repeat: int) -> dict:
    """The least time of each run over `repeat` rounds, every run once a round: a slow spell
    of a shared machine falls on all of them alike (None: not run)."""
    best = {key: math.inf for key in runs}
    for _ in range(repeat):
        for key, run in runs.items():
            if run is not None:
                best[key] = min(best[key], fastest(run, 1))
    return {key: (best[key] if runs[key] is not None else None) for key in runs}


def substeps_per_step(scene, seconds: float) -> float:
    """The RK4 sub-steps the run's motion takes per step (the tolerance's included), counted
    on the Python path step by step (the compiled path takes the same)."""
    sim, split = simulator(scene, False), []
    before = [0]

    def count(s):
        split.append(s.substeps_taken > before[0])
        before[0] = s.substeps_taken
    sim.run(seconds, count)
    return (sim.substeps_taken + split.count(False)) / max(1, sim.steps)


def time_limit(scene, seconds: float, repeat: int):
    """CPU seconds of the bare compiled loop (prepared_limit), or None."""
    run = prepared_limit(scene, seconds)
    return run and fastest(run, repeat)


def prepared_limit(scene, seconds: float):
    """The bare compiled RK4 loop on the scene's rhs (compiled.bare: steps, nothing else)."""
    sim = simulator(scene, False)
    dynamics = build_dynamics(scene)
    if not compiled.compilable(dynamics, sim._step):   # a servo's set-points: Python's path
        return None
    source, names = compiled.module_source(dynamics, sim._step)
    module = compiled.load(source)
    command = compiled.constants_of(names, {**dynamics.function.__globals__,
                                            **getattr(sim._step, "constants", {})})
    y0 = np.array(sim.state, dtype=float)
    steps = scene.steps_for(seconds) * sim.substeps
    h = scene.step_size / sim.substeps
    module.bare(y0.copy(), h, 1, command)
    return lambda: module.bare(y0.copy(), h, steps, command)


def prepared_mujoco(scene, seconds: float):
    """(mj_step RK4 for `seconds`, ""), or (None, why not)."""
    import mujoco
    if scene.friction is not None or scene.joint_limits is not None:
        return None, "soft friction/limits"
    try:
        model, ctrl = mujoco_peer.mujoco_model(scene, "RK4")
    except mujoco_peer.Unsupported as error:
        return None, str(error).split(" (")[0][:22]
    data = mujoco_peer.mujoco_data(model, scene, ctrl)
    steps, step = scene.steps_for(seconds), mujoco.mj_step

    def run():
        mujoco_peer.reset(model, data, scene, ctrl)
        for _ in range(steps):
            step(model, data)
    return run, ""


def presets_table(seconds: float, repeat: int, only=None) -> list[str]:
    head = (f"{'preset':<30}{'h':>7}{'sub':>4} {'python':>9} {'compiled':>9} {'off':>8} "
            f"{'mujoco':>9} {'limit':>8} {'speed-up':>8} {'sub/step':>8} {'of same':>8} "
            f"{'off of':>7}  path / first compile")
    lines = [f"Simulator.run, µs per simulated second (steps/s below each), {seconds:g} s runs, "
             f"best of {repeat}", head, "-" * len(head)]
    for name in only or preset_names():
        scene = load_scene(name)
        compiled_run, path, first = prepared_run(scene, seconds, True)
        mujoco_run, why = prepared_mujoco(scene, seconds)
        best = interleaved({     # in rounds: the ratios within a row under the same load
            "python": prepared_run(scene, seconds, False)[0], "compiled": compiled_run,
            "off": prepared_run(scene.replace(estimate="off", tolerance=0.0), seconds, True)[0],
            "limit": prepared_limit(scene, seconds), "mujoco": mujoco_run}, repeat)
        py, fast, off, limit, theirs = (best[k] for k in ("python", "compiled", "off", "limit",
                                                           "mujoco"))
        steps = scene.steps_for(seconds)
        per = lambda t, w=9: f"{t / seconds * 1e6:>{w}.0f}" if t is not None else f"{'-':>{w}}"
        rate = lambda t, w=9: f"{steps / t:>{w}.3g}" if t is not None else f"{'':>{w}}"
        sub = Simulator(scene).substeps
        ratio = lambda a, b, w=8: f"{a / b:>{w - 1}.1f}x" if b else f"{'-':>{w}}"
        taken = substeps_per_step(scene, seconds)     # the limit at the run's own count
        same = limit * taken / sub if limit else None
        lines.append(f"{name:<30}{scene.step_size:>7g}{sub:>4} {per(py)} {per(fast)} "
                     f"{per(off, 8)} {per(theirs)} {per(limit, 8)} {py / fast:>7.1f}x "
                     f"{taken:>8.2f} {ratio(fast, same)} {ratio(off, limit, 7)}  "
                     f"{'compiled' if 'numba' in path else 'python'} {first:.2f} s {why}")
        lines.append(f"{'':<41} {rate(py)} {rate(fast)} {rate(off, 8)} {rate(theirs)} "
                     f"{rate(limit, 8)}")
    return lines


def step_table(repeat: int, steps: int = 2000) -> list[str]:
    """Simulator.step (the node's path) one call per step, compiled and pure Python, beside
    Simulator.run (compiled, the same steps in one call), mj_step called from Python and the
    compiled limit, h = 1 ms, interleaved, best of `repeat` rounds of `steps` steps."""
    lines = [f"Simulator.step at h = 1 ms, µs per step (CPU), {steps} steps, interleaved, best "
             f"of {repeat}", f"{'scene':<12}{'estimate':>9} {'python':>8} {'compiled':>9} "
             f"{'run':>7} {'mj_step':>8} {'limit':>7} {'python/compiled':>16} "
             f"{'mj_step/compiled':>17} {'compiled/run':>13}", "-" * 112]
    for name in ("release", "stick_slip"):
        for estimate in ("global", "off"):
            scene = load_scene(name).replace(step_size=0.001)
            if estimate == "off":
                scene = scene.replace(estimate="off", tolerance=0.0)
            timed = {"python": stepped(simulator(scene, False), steps),
                     "compiled": stepped(simulator(scene, True), steps),
                     "run": ran(simulator(scene, True), steps)}
            if name == "release":
                timed["mj_step"] = mujoco_steps(scene, steps)
            limit = time_limit(scene, steps * scene.step_size, 1)
            best = {key: math.inf for key in timed}
            for _ in range(repeat):                   # interleaved: the same load for each
                for key, run in timed.items():
                    best[key] = min(best[key], fastest(run, 1))
            per = {key: best[key] / steps * 1e6 for key in best}
            mj = per.get("mj_step", math.nan)
            lines.append(
                f"{name:<12}{estimate:>9} {per['python']:>8.2f} {per['compiled']:>9.2f} "
                f"{per['run']:>7.3f} {mj:>8.2f} "
                f"{limit / steps * 1e6 if limit else math.nan:>7.3f} "
                f"{per['python'] / per['compiled']:>15.1f}x {mj / per['compiled']:>16.2f}x "
                f"{per['compiled'] / per['run']:>12.1f}x")
    return lines


def ran(sim, steps: int):
    """Simulator.run over `steps` steps from the scene's start, one compiled call (warmed)."""
    def run():
        sim.reset()
        sim.run(steps * sim.step_size)
    run()
    return run


def stepped(sim, steps: int):
    """A run of `steps` Simulator.step calls from the scene's start (warmed once)."""
    def run():
        sim.reset()
        for _ in range(steps):
            sim.step()
    run()
    return run


def mujoco_steps(scene, steps: int):
    import mujoco
    model, ctrl = mujoco_peer.mujoco_model(scene, "RK4")
    data = mujoco_peer.mujoco_data(model, scene, ctrl)
    step = mujoco.mj_step

    def run():
        mujoco_peer.reset(model, data, scene, ctrl)
        for _ in range(steps):
            step(model, data)
    return run


def unnamed_windings_table(seconds: float, repeat: int, long: float = 20.0) -> list[str]:
    """A windings scene that names no integrator (motor_windings_hold, h = 1 ms: L/R =
    0.53 ms, and the issue's L/R = 10 µs) against the plain arm (the same pose and policy,
    no motors), the windings at 0.53 ms, and the same windings on rk4 with its sub-steps:
    Simulator.run at the default tolerance, compiled over `long` seconds (the windings'
    first transient, which the tolerance sub-steps, amortised as in the issue's 20 s), pure
    Python over `seconds`."""
    windings = load_scene("motor_windings_hold")
    plain = windings.replace(motors=None)
    stiff = windings.replace(motors=dict(windings.motors, inductance=tuple(
        1e-5 * r for r in windings.motors["resistance"])))      # L/R = 10 µs
    rows = [("plain arm (no motors)", plain)]
    for what, scene in (("L/R 0.53 ms", windings), ("L/R 10 µs", stiff)):
        rows += [(f"windings {what}, unnamed ({scene.method})", scene),
                 (f"windings {what}, rk4 named", scene.replace(integrator="rk4"))]
    lines = [f"A windings scene naming no integrator, h = 1 ms, Simulator.run, µs per simulated "
             f"second: python {seconds:g} s runs, compiled {long:g} s runs, best of {repeat}",
             f"{'scene':<48}{'sub':>4} {'python':>9} {'of plain':>9} {'compiled':>9} "
             f"{'of plain':>9} {'of 0.53 ms':>10}", "-" * 104]
    base = {}
    for label, scene in rows:
        py, _, _ = time_run(scene, seconds, repeat, False)
        fast, _, _ = time_run(scene, long, repeat, True)
        base = base or {"py": py, "fast": fast}
        if scene is windings:
            base["ms"] = fast
        lines.append(f"{label:<48}{Simulator(scene).substeps:>4} {py / seconds * 1e6:>9.0f} "
                     f"{py / base['py']:>8.2f}x {fast / long * 1e6:>9.0f} "
                     f"{fast / base['fast']:>8.2f}x "
                     + (f"{fast / base['ms']:>9.2f}x" if "ms" in base else f"{'-':>10}"))
    return lines


def batch_table(arms: int, steps: int, repeat: int) -> list[str]:
    """Batch (numpy, compiled on 1 and 2 threads) against mujoco.rollout, effect-free: M
    arm-steps per CPU second of the process (its threads' summed; what a shared machine's
    load changes least) and per wall second (what threads buy on an idle machine)."""
    import mujoco
    from mujoco import rollout

    scene = load_scene("release").replace(tolerance=0.0)
    rng = np.random.default_rng(0)
    positions = np.asarray(scene.initial_positions) + rng.uniform(-0.5, 0.5, (arms, 2))
    lines = [f"Batch, {arms} arms x {steps} steps of release (h = {scene.step_size:g} s), "
             f"best of {repeat}: M arm-steps per second", f"{'':<28}{'CPU s':>8}{'wall s':>8}",
             "-" * 44]

    def row(label, run):
        cpu = fastest(run, repeat, time.process_time)
        wall = fastest(run, repeat, time.perf_counter)
        lines.append(f"{label:<28}{arms * steps / cpu / 1e6:>8.2f}{arms * steps / wall / 1e6:>8.2f}")
    for label, fast, threads in (("numpy", False, 1), ("numpy, 2 threads", False, 2),
                                 ("compiled, 1 thread", True, 1), ("compiled, 2 threads", True, 2)):
        os.environ["ARM_SIM_COMPILED"] = "1" if fast else "0"
        batch = Batch(scene, positions)
        os.environ.pop("ARM_SIM_COMPILED")
        batch.run(0, threads)

        def run():
            batch.reset()
            batch.run(steps, threads)
        row(label, run)
    model, ctrl = mujoco_peer.mujoco_model(scene, "RK4")
    datas = [mujoco.MjData(model) for _ in range(2)]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    initial = np.zeros((arms, mujoco.mj_stateSize(model, spec)))
    for i in range(arms):
        mujoco_peer.reset(model, datas[0], scene, ctrl)
        datas[0].qpos[:] = positions[i]
        mujoco.mj_getState(model, datas[0], initial[i], spec)
    for threads in (1, 2):
        with rollout.Rollout(nthread=threads) as pool:
            pool.rollout(model, datas[:threads], initial, nstep=steps)
            row(f"mujoco.rollout, {threads} thread(s)",
                lambda: pool.rollout(model, datas[:threads], initial, nstep=steps))
    return lines


def windings_table(repeat: int) -> list[str]:
    """|q - DOP853 reference| and cost at equal h: rk4 (sub-steps), exponential_rk4 (none),
    MuJoCo's dcmotor (RK4, first-order current update). Tolerance off: the methods alone."""
    import mujoco
    from bench_effects import WINDINGS, windings_reference

    seconds = 0.2
    scene = load_scene("release").replace(motors=WINDINGS, policy="constant",
                                          constant_torque=(20.0, 5.0), tolerance=0.0)
    reference = windings_reference(scene, seconds)
    lines = [f"windings (maxon, L/R = 0.53 ms; constant 20, 5 N m): max |q - reference| at "
             f"t = {seconds:g} s and µs per simulated second (python path, tolerance off)",
             f"{'h (ms)':>7} | {'rk4 sub':>7} {'error':>8} {'µs/s':>8} | {'exp sub':>7} "
             f"{'error':>8} {'order':>5} {'µs/s':>8} | {'dcmotor error':>13} {'µs/s':>8}",
             "-" * 96]
    previous = None
    for h in (4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4):
        row = [f"{h * 1e3:>7g} |"]
        for integrator in ("rk4", "exponential_rk4"):
            at = scene.replace(step_size=h, integrator=integrator)
            sim = simulator(at, False)
            elapsed = fastest(lambda: (sim.reset(), sim.run(seconds)), repeat)
            error = max(abs(sim.state[i] - reference[i]) for i in (0, 1))
            order = (f"{math.log2(previous / error):>5.1f}" if integrator != "rk4" and previous
                     else f"{'':>5}" if integrator != "rk4" else "")
            if integrator != "rk4":
                previous = error
            row.append(f"{sim.substeps:>7d} {error:>8.1e} {order}{' ' if order else ''}"
                       f"{elapsed / seconds * 1e6:>8.0f} |")
        at = scene.replace(step_size=h)
        model, ctrl = mujoco_peer.mujoco_model(at, "RK4")
        data = mujoco_peer.mujoco_data(model, at, ctrl)

        def run():
            mujoco_peer.reset(model, data, at, ctrl)
            for _ in range(at.steps_for(seconds)):
                mujoco.mj_step(model, data)
        elapsed = fastest(run, repeat)
        error = max(abs(data.qpos[i] - reference[i]) for i in (0, 1))
        row.append(f" {error:>13.1e} {elapsed / seconds * 1e6:>8.0f}")
        lines.append(" ".join(row))
    return lines


FIRST_COMPILE_RUNS = (("release", 2.0), ("stick_slip", 2.0), ("geared_arm", 0.3))


def first_compile_table() -> list[str]:
    """What a scene's first compile costs: `arm-sim run` in a new process with an empty kernel
    cache (cold), then again with the cache it filled (warm); CPU seconds of the process
    (numba compiles on one thread) and wall seconds. compile = cold - warm CPU: what
    physics/compiled/cache.py's FIRST_COMPILE_CPU estimates (test/project/test_figures.py)."""
    import resource
    import subprocess
    import tempfile

    def timed(scene: str, seconds: float, cache: str) -> tuple:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "arm_sim_ros.tools.cli", "run", "--scene", scene,
                        "--duration", str(seconds)], check=True, capture_output=True,
                       env=os.environ | {"ARM_SIM_CACHE": cache})
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        return (after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime,
                time.perf_counter() - start)

    lines = ["First compile: arm-sim run in a new process, empty kernel cache (cold), then the "
             "cache it filled (warm); s",
             f"{'scene':<14}{'simulated':>10}{'cold CPU':>10}{'cold wall':>10}{'warm CPU':>10}"
             f"{'warm wall':>10}{'compile':>10}"]
    for scene, seconds in FIRST_COMPILE_RUNS:
        with tempfile.TemporaryDirectory() as cache:
            cold, warm = timed(scene, seconds, cache), timed(scene, seconds, cache)
        lines.append(f"{scene:<14}{seconds:>10g}{cold[0]:>10.1f}{cold[1]:>10.1f}{warm[0]:>10.1f}"
                     f"{warm[1]:>10.1f}{cold[0] - warm[0]:>10.1f}")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--arms", type=int, default=20000)
    parser.add_argument("--batch-steps", type=int, default=500)
    parser.add_argument("--only", help="these presets (comma-separated) alone, no other table")
    parser.add_argument("--tables", default=",".join(TABLES),
                        help=f"which tables, comma-separated, of {', '.join(TABLES)} (all)")
    args = parser.parse_args()
    if not compiled.available():
        sys.exit("bench_speed: numba is not installed: pip install -e '.[fast]'")
    import mujoco
    import numba
    print(f"numba {numba.__version__}, mujoco {mujoco.__version__}, numpy {np.__version__}, "
          f"{os.cpu_count()} CPUs")
    if args.only:
        print("\n".join(presets_table(args.seconds, args.repeat, args.only.split(","))))
        return
    tables = {"step": lambda: step_table(max(5, args.repeat)),
              "presets": lambda: presets_table(args.seconds, args.repeat),
              "unnamed": lambda: unnamed_windings_table(args.seconds, args.repeat),
              "batch": lambda: batch_table(args.arms, args.batch_steps, args.repeat),
              "windings": lambda: windings_table(args.repeat),
              "first_compile": first_compile_table}
    for name in args.tables.split(","):
        if name not in tables:
            sys.exit(f"bench_speed: no table {name!r}; choose from {', '.join(TABLES)}")
        print("\n".join(tables[name]()) + "\n", flush=True)


TABLES = ("step", "presets", "unnamed", "batch", "windings", "first_compile")


if __name__ == "__main__":
    main()
