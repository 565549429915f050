"""The runs of the accuracy study (command.py): its reference, and each run of ours or of
MuJoCo, sampled at the same times and compared with the reference. Each comes back with its
price still to take (timing.py): the whole run, as a user makes it.

  ours     Simulator.run over the whole duration in one call, on the path the user has
           (compiled where numba is installed; `path` says which), with the error estimate
           (`estimate` global) or without (off);
  node     the scene as set through Simulator.step, one Python call per step: what the node
           pays per tick (a line of the price list beside the runs, not a run);
  MuJoCo   mj_step in a Python loop, as a user of its Python bindings steps it, and
           mujoco.rollout, its C loop over every step in one call.

Ours are sampled by Simulator.run up to each sample time; the timed run must end in the state
the samples end in, bit for bit: what is priced is what was measured.
"""
from __future__ import annotations

from dataclasses import dataclass
from math import ceil, isfinite, nan

from ...physics import model
from ...physics.trust.accuracy import MAX_SUBSTEPS
from ...physics.trust.unestimated import ESTIMATES  # noqa: F401  (ours run with each)
from ...physics.stepping.integrators import INTEGRATORS
from ...physics.scene import Scene, SceneError
from ...physics.simulator import Simulator
from . import mujoco_peer
from .independent import TOLERANCE as INDEPENDENT_TOLERANCE
from .independent import Independent, covers
from .timing import Priced

REFERENCE_TOLERANCE = 1e-13
MODEL_EFFECTS = {"gravity", "damping", "actuator"}    # what model.forward_dynamics covers
HYBRID_STEP = 2.5e-4   # the largest step of the reference of scenes that switch modes
# What a run is (Run.kind) and its line's name after the integrator's (Run.series).
SERIES = {"method": "", "as set": " (scene as set)", "tolerance": " + tolerance",
          "node": " (scene as set, Simulator.step)", "mujoco": "", "mujoco rollout": " rollout"}
OFF = ", estimate off"            # the series name of a run without
MJ_STEP, ROLLOUT = "mj_step from Python", "mujoco.rollout"     # MuJoCo's paths


@dataclass
class Run:
    integrator: str
    step_size: float
    tolerance: float | None       # None for fixed-step methods
    max_state_error: float        # max over sample times and q1, q2, qd1, qd2 of |y - y_ref|
    energy_drift: float | None    # max over sample times of |E - E_ref| (J)
    balance_residual: float | None  # max over every step of |E - E(0) - W + dissipated| (J)
    cpu_s_per_sim_s: float = nan  # the whole run's price (timing.py), per simulated second
    series: str = ""              # its line: "rk4", "rk4, estimate off", "mujoco RK4 rollout"
    substeps: int | None = None   # sub-steps taken (Simulator.substeps_taken)
    kind: str = "method"          # a SERIES key
    path: str = ""                # ours: Simulator.path; MuJoCo: MJ_STEP or ROLLOUT
    estimate: str | None = None   # ours: an ESTIMATES value; a peer: None (not ours to choose)

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


def worst(values) -> float:
    # A non-finite result is infinitely wrong, not silently skipped by max().
    return max((v if isfinite(v) else float("inf") for v in values), default=0.0)


def errors(sim: Simulator, samples, ref) -> tuple[float, float | None]:
    """(max state error, max energy drift) of `samples` against the reference rows."""
    state = worst(abs(a - b) for s, r in zip(samples, ref) for a, b in zip(s[:4], r[:4]))
    if any(len(s) < 4 + len(sim.extra) for s in samples[:1]):
        return state, None              # a peer without our extra states: no energy
    return state, worst(abs(sim.energy(s) - sim.energy(r)) for s, r in zip(samples, ref))


def series_of(integrator: str, kind: str, estimate: str | None) -> str:
    return integrator + SERIES[kind] + (OFF if estimate == "off" else "")


def measure(scene: Scene, name: str, step_size: float, tolerance: float | None, times,
            ref, estimate: str = "global") -> Priced:
    """One method at one step size (an embedded pair: at one rtol = atol), the tolerance
    off (0), with the error estimate (`estimate` global: the estimate alone, which never
    changes a step) or without (off): one trajectory at two prices."""
    tolerances = {} if tolerance is None else {"rtol": tolerance, "atol": tolerance}
    at = scene.replace(integrator=name, step_size=step_size, tolerance=0.0, estimate=estimate,
                       **tolerances)
    return measure_simulator(at, times, ref, "method")


def measure_simulator(scene: Scene, times, ref, kind: str = "as set") -> Priced:
    """The scene (its integrator, step, tolerance and estimate) through Simulator.run:
    sampled by run up to each sample time, priced as one run over the whole duration; `kind`
    (a SERIES key) names it."""
    sim = Simulator(scene)
    interval = times[1] - times[0] if len(times) > 1 else 0.0
    samples, residual = [sim.state], 0.0
    for _ in times[1:]:
        residual = max(residual, sim.run(interval))
        samples.append(sim.state if not sim.refused_steps else (float("inf"),) * len(sim.state))
    held = sim.refused_steps or sim.diverged     # the state held is not the motion
    final, substeps, duration = sim.state, sim.substeps_taken, times[-1] - times[0]
    sim.reset()
    sim.run(duration)
    if not held and sim.state != final:
        raise RuntimeError(f"{scene.name}: Simulator.run over {duration:g} s in one call ended "
                           "apart from the run sampled up to each sample time")
    return Priced(simulator_run(sim, scene, samples, ref, residual, substeps, kind, held),
                  lambda: sim.run(duration), sim.reset)


def simulator_run(sim: Simulator, scene: Scene, samples, ref, residual: float, substeps,
                  kind: str, held=False) -> Run:
    """The Run of a simulator's samples of `scene`."""
    state_error, drift = errors(sim, samples, ref)
    adaptive = INTEGRATORS[scene.integrator].adaptive
    tolerance = scene.rtol if adaptive else None if kind == "method" else scene.tolerance
    return Run(scene.integrator, scene.step_size, tolerance, state_error, drift,
               float("inf") if held else residual, series=series_of(
                   scene.integrator, kind, scene.estimate),
               substeps=substeps, kind=kind, path=sim.path, estimate=scene.estimate)


def measure_node(scene: Scene, times, ref) -> Priced:
    """The scene as set through Simulator.step, one Python call per step, as the node ticks;
    priced as the steps of the whole duration."""
    sim = Simulator(scene)
    every, total = cadence(scene, times)
    samples, residual = stepped(sim, len(times) - 1, every)
    run = simulator_run(sim, scene, samples, ref, residual, sim.substeps_taken, "node",
                        sim.refused_steps or sim.diverged)

    def go():
        step = sim.step
        for _ in range(total):
            step()
    return Priced(run, go, sim.reset)


def measure_mujoco(scene: Scene, integrator: str, step_size: float, times,
                   ref) -> list[Priced]:
    """MuJoCo's `integrator` at `step_size`, sampled as ours are; priced twice: mj_step in
    a Python loop and mujoco.rollout."""
    at = scene.replace(step_size=step_size)
    every, total = cadence(scene, times, step_size)
    ours, name, priced = Simulator(scene), f"mujoco {integrator}", []
    for runner, kind, path in ((mujoco_peer.Runner(at, integrator), "mujoco", MJ_STEP),
                               (mujoco_peer.Rollout(at, integrator), "mujoco rollout", ROLLOUT)):
        state_error, drift = errors(ours, runner.run(total, every), ref)
        run = Run(name, step_size, None, state_error, drift, None, series=name + SERIES[kind],
                  kind=kind, path=path)
        priced.append(Priced(run, lambda runner=runner: runner.go(total, every)))
    return priced
