"""The runs of the accuracy study (accuracy.py): the reference, and one method, the scene as
set, or MuJoCo, each sampled at the same times, compared with the reference and timed the
same way: CPU time of a Python loop of one call per step that keeps the samples, the
fastest of several runs.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from math import ceil, isfinite

from ...physics import model
from ...physics.trust.accuracy import MAX_SUBSTEPS
from ...physics.stepping.integrators import INTEGRATORS, step_for
from ...physics.scene import Scene, SceneError
from ...physics.simulator import Simulator
from . import mujoco_peer
from .independent import TOLERANCE as INDEPENDENT_TOLERANCE
from .independent import Independent, covers

REFERENCE_TOLERANCE = 1e-13
MODEL_EFFECTS = {"gravity", "damping", "actuator"}    # what model.forward_dynamics covers
MIN_TIMED_CPU_S = 0.05          # repeat short runs until this much CPU time, keep the fastest
HYBRID_STEP = 2.5e-4   # the largest step of the reference of scenes that switch modes
# What a run is (Run.kind) and its line's name after the integrator's (Run.series).
SERIES = {"method": "", "as set": " (scene as set)", "tolerance": " + tolerance"}


@dataclass
class Run:
    integrator: str
    step_size: float
    tolerance: float | None       # None for fixed-step methods
    max_state_error: float        # max over sample times and q1, q2, qd1, qd2 of |y - y_ref|
    energy_drift: float | None    # max over sample times of |E - E_ref| (J)
    balance_residual: float | None  # max over every step of |E - E(0) - W + dissipated| (J)
    rhs_evaluations: int | None   # counted on the bare tableau step only
    cpu_s_per_sim_s: float
    series: str = ""              # its line: the integrator, "rk4 + tolerance", "mujoco RK4"
    substeps: int | None = None   # sub-steps taken (Simulator.substeps_taken)
    kind: str = "method"          # a SERIES key (the tableau's sweeps), or "mujoco"

    def __post_init__(self):
        self.series = self.series or self.integrator


def sample_times(scene: Scene, duration: float, interval: float) -> list[float]:
    count = scene.steps_for(duration, interval)
    return [k * interval for k in range(count + 1)]


def switches(scene: Scene) -> bool:
    """True where the scene switches modes at located events (friction, joint limits)."""
    return Simulator(scene).switching is not None


def reference(scene: Scene, times) -> list[tuple]:
    """(q1, q2, qd1, qd2, *extra, *channels) at `times`: scipy's DOP853 at rtol = atol =
    1e-13, or for a scene that switches modes, our rk4 at a fine step with the switches
    located (hybrid_reference)."""
    return reference_and_label(scene, times)[0]


def reference_and_label(scene: Scene, times) -> tuple[list[tuple], str]:
    if switches(scene):
        if covers(scene) is None:         # friction and limits on separately written equations
            return (Independent(scene).states(times),
                    "scipy DOP853, switches as terminal events and restarts, on equations "
                    f"written apart (tools/accuracy/independent.py), rtol=atol={INDEPENDENT_TOLERANCE:g}")
        return hybrid_reference(scene, times)
    import numpy as np
    from scipy.integrate import solve_ivp

    sim = Simulator(scene)
    arm, gravity, damping = scene.arm, scene.gravity, scene.damping
    torque_of = sim.dynamics.applied_torque
    channels = sim.channels

    def rates(t, y):
        q, qd = (y[0], y[1]), (y[2], y[3])
        tau = torque_of(q)
        qdd = model.forward_dynamics(arm, q, qd, tau, gravity, damping)
        books = {"work": tau[0] * qd[0] + tau[1] * qd[1],
                 "dissipated": damping * (qd[0] * qd[0] + qd[1] * qd[1])}
        return [qd[0], qd[1], qdd[0], qdd[1], *(books[c] for c in channels)]

    if not set(sim.dynamics.effects) <= MODEL_EFFECTS or not isinstance(damping, float):
        # The model's equations cover the explainer's effects; the others are checked
        # against separately written equations in test/physics/test_effects.py, so here the
        # reference integrates the generated right-hand side (integration error only).
        f = sim.dynamics.function
        width = 4 + len(sim.extra)          # f takes q, q̇ and the extra states, not channels
        rates = lambda t, y: (y[2], y[3], *f(*y[:width]))  # noqa: E731  (f gives the rest)

    solution = solve_ivp(rates, (times[0], times[-1]), list(sim.state), method="DOP853",
                         t_eval=times, rtol=REFERENCE_TOLERANCE, atol=REFERENCE_TOLERANCE)
    if not solution.success:
        raise SceneError(f"the reference integration failed: {solution.message}")
    return ([tuple(row) for row in np.asarray(solution.y).T],
            f"scipy solve_ivp DOP853 rtol=atol={REFERENCE_TOLERANCE:g}")


def hybrid_reference(scene: Scene, times) -> tuple[list[tuple], str]:
    """For a switching scene tools/accuracy/independent.py does not cover (motors, clamps): our rk4
    at a fine step with every switch located (order 4 across switches,
    test/physics/test_friction_limits.py) and a tolerance at rounding, so contacts are resolved as
    finely as the rest (at tolerance 0 a compliant contact's sub-step is fixed, whatever h:
    a plateau), checked against itself at half the step (the label says how far apart)."""
    interval = times[1] - times[0] if len(times) > 1 else 0.0
    h = interval / ceil(interval / HYBRID_STEP - 1e-9) if interval else scene.step_size
    runs = []
    for step in (h, h / 2):
        sim = Simulator(scene.replace(integrator="rk4", step_size=step, tolerance=1e-10,
                                      max_substeps=MAX_SUBSTEPS))
        runs.append(stepped(sim, len(times) - 1, round(interval / step) if interval else 1,
                            books=False)[0])
    gap = max(abs(a - b) for s, r in zip(*runs) for a, b in zip(s[:4], r[:4]))
    return runs[1], (f"ours rk4, switches located, h={h / 2:g} (itself at h={h:g}: within "
                     f"{gap:.1e})")


def stepped(sim: Simulator, samples: int, every: int, books: bool = True) -> tuple[list, float]:
    """(states at the start and every `every`-th step, largest |residual| at any step; 0.0
    unless `books`)."""
    kept, residual = [sim.state], 0.0
    for n in range(1, samples * every + 1):
        sim.step()
        if books:
            residual = max(residual, abs_residual(sim))
        if n % every == 0:
            kept.append(sim.state)
    return kept, residual


def abs_residual(sim: Simulator) -> float:
    """|the balance residual| of the simulator's state; a non-finite one is infinite."""
    books = abs(sim.residual())
    return books if isfinite(books) else float("inf")


def cadence(scene: Scene, times, step_size: float | None = None) -> tuple[int, int]:
    """(steps between samples, steps in all) of a run at `step_size` (else the scene's)."""
    every = scene.steps_for(times[1] - times[0], step_size) if len(times) > 1 else 1
    return every, every * (len(times) - 1)


def per_simulated_second(seconds: float, times) -> float:
    duration = times[-1] - times[0]
    return seconds / duration if duration > 0 else 0.0


class _Counted:
    """f with a call counter (used only in the untimed pass)."""

    def __init__(self, f):
        self.f, self.calls = f, 0

    def __call__(self, *y):
        self.calls += 1
        return self.f(*y)


def fastest_cpu(run, repeat: int = 1) -> float:
    """CPU seconds of the fastest call of run(): at least `repeat` calls and MIN_TIMED_CPU_S
    in all (ours and MuJoCo's are timed by this one routine)."""
    best, spent, calls = float("inf"), 0.0, 0
    while calls < repeat or spent < MIN_TIMED_CPU_S:
        start = time.process_time()
        run()
        elapsed = time.process_time() - start
        best, spent, calls = min(best, elapsed), spent + elapsed, calls + 1
    return best


def worst(values) -> float:
    # A non-finite result is infinitely wrong, not silently skipped by max().
    return max((v if isfinite(v) else float("inf") for v in values), default=0.0)


def errors(sim: Simulator, samples, ref) -> tuple[float, float | None]:
    """(max state error, max energy drift) of `samples` against the reference rows."""
    state = worst(abs(a - b) for s, r in zip(samples, ref) for a, b in zip(s[:4], r[:4]))
    if any(len(s) < 4 + len(sim.extra) for s in samples[:1]):
        return state, None              # a peer without our extra states: no energy
    return state, worst(abs(sim.energy(s) - sim.energy(r)) for s, r in zip(samples, ref))


def measure(scene: Scene, name: str, step_size: float, tolerance: float | None, times,
            ref, repeat: int = 1) -> Run:
    """One method at one step size (or tolerance) against the reference samples; the bare
    tableau step, except where the scene switches modes (only Simulator.step does that)."""
    tolerances = {} if tolerance is None else {"rtol": tolerance, "atol": tolerance}
    if switches(scene):
        run = measure_simulator(scene.replace(integrator=name, step_size=step_size,
                                              tolerance=0.0, **tolerances), times, ref, repeat,
                                "method")
        run.tolerance = tolerance
        return run
    sim = Simulator(scene.replace(integrator=name, step_size=step_size))
    step = step_for(INTEGRATORS[name], len(sim.channels), sim.dynamics.decay, **tolerances)
    every, total = cadence(scene, times, step_size)
    y0 = sim.state

    # Untimed pass: evaluations, the balance residual after every step, the samples.
    counted = _Counted(sim.dynamics.function)
    y, samples, residual = y0, [y0], 0.0
    for n in range(1, total + 1):
        y = step(counted, y, step_size)
        sim.state = y
        residual = max(residual, abs_residual(sim))
        if n % every == 0:
            samples.append(y)
    sim.state = y0

    f = sim.dynamics.function

    def run():          # timed: stepping and sampling only
        y, kept = y0, []
        for n in range(1, total + 1):
            y = step(f, y, step_size)
            if n % every == 0:
                kept.append(y)

    best = fastest_cpu(run, repeat)
    state_error, drift = errors(sim, samples, ref)
    return Run(name, step_size, tolerance, state_error, drift, residual, counted.calls,
               per_simulated_second(best, times))


def measure_simulator(scene: Scene, times, ref, repeat: int = 1, kind: str = "as set") -> Run:
    """The scene as set, through Simulator.step (estimator, tolerance, sub-steps, events);
    `kind` (a SERIES key) names the run."""
    sim = Simulator(scene)
    every, total = cadence(scene, times)
    samples, residual = stepped(sim, len(times) - 1, every)
    substeps = sim.substeps_taken

    def run():
        sim.reset()
        step, kept = sim.step, []
        for n in range(1, total + 1):
            step()
            if n % every == 0:
                kept.append(sim.state)

    best = fastest_cpu(run, repeat)
    state_error, drift = errors(sim, samples, ref)
    adaptive = INTEGRATORS[scene.method].adaptive
    return Run(scene.method, scene.step_size, scene.rtol if adaptive else scene.tolerance,
               state_error, drift, residual, None, per_simulated_second(best, times),
               scene.method + SERIES[kind], substeps, kind)


def measure_mujoco(scene: Scene, integrator: str, step_size: float, times, ref,
                   repeat: int = 1) -> Run:
    """MuJoCo's `integrator` at `step_size`, sampled and timed as ours are."""
    runner = mujoco_peer.Runner(scene.replace(step_size=step_size), integrator)
    every, total = cadence(scene, times, step_size)
    samples = runner.run(total, every)
    best = fastest_cpu(lambda: runner.run(total, every), repeat)
    state_error, drift = errors(Simulator(scene), samples, ref)
    name = f"mujoco {integrator}"
    return Run(name, step_size, None, state_error, drift, None, None,
               per_simulated_second(best, times), name, kind="mujoco")
