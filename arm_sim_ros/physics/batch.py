"""Batch rollouts: N arms of one scene stepped together with numpy.

Nothing here re-derives the physics. The right-hand side is the scene's own generated
source (dynamics.build_dynamics) executed with numpy's cos/sin and per-arm constants, and
the step is the same compiled RK4 straight-line code, applied to arrays instead of floats.
Arms are independent, so they are stepped in cache-sized chunks (each chunk runs every
step before the next chunk starts) and, optionally, chunks run on several threads: numpy
releases the GIL inside its loops.

Scenes of any effects, each with its own values, run to their Outcomes with run_scenes
(rollouts/), which this module exports.
"""
from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from types import SimpleNamespace

import numpy as np

from .compiled import build as compiled
from .stepping import stability
from .dynamics import build_dynamics
from .effects import Damping, Gravity
from .stepping.integrators import INTEGRATORS
from .stepping.exponential import step_for
from .model import ArmParameters, fold_payload
from .scene import Scene, SceneError
from .simulator import Simulator
from .rollouts import Outcome, run_scenes  # noqa: F401  (many scenes, each to its Outcome)

CHUNK = 32768                 # arms per chunk: a few hundred KB per array, stays in L2
PAIR_PARAMETERS = ("link_lengths", "link_masses", "com_distances", "com_inertias",
                   "constant_torque")
SCALAR_PARAMETERS = ("gravity", "damping")
LINK_PARAMETERS = PAIR_PARAMETERS[:4]


def _per_arm(name: str, value, count: int, pair: bool) -> np.ndarray:
    """(count,) or (count, 2) float array from a scalar/pair or a per-arm array; refuses non-finite."""
    shape = (count, 2) if pair else (count,)
    array = np.asarray(value, dtype=float)
    try:
        array = np.broadcast_to(array, shape)
    except ValueError:
        raise SceneError(f"{name} must have shape {shape} (or broadcast to it), got "
                         f"{array.shape}") from None
    bad = ~np.isfinite(array)
    if bad.any():
        arm = int(np.argwhere(bad)[0][0])
        raise SceneError(f"{name} of arm {arm} is not finite")
    return array


def sampled_arm_by_arm(scene) -> str:
    """What of the scene takes samples arm by arm, which a batch cannot ('' if nothing): a
    discrete servo, sensors, a command delay."""
    return " or ".join(what for what, named in (
        ("a discrete servo (servo.rate)", (scene.servo or {}).get("rate")),
        ("sensors", scene.sensors is not None), ("a command_delay", scene.command_delay))
        if named)


def _refuse_where(mask: np.ndarray, message: str) -> None:
    if mask.any():
        arm = int(np.argmax(mask.reshape(len(mask), -1).any(axis=1)))
        raise SceneError(f"arm {arm}: {message}")


class Batch:
    """N copies of `scene`, each with its own initial state and, optionally, parameters.

    positions, velocities: (N, 2) arrays (default: the scene's, for `count` arms).
    parameters: any of gravity, damping (N,) and link_lengths, link_masses, com_distances,
    com_inertias, constant_torque (N, 2), per arm; the rest come from the scene. The
    effects present are the scene's, plus any a per-arm value switches on.
    """

    def __init__(self, scene: Scene, positions=None, velocities=None, count: int | None = None,
                 **parameters):
        unknown = sorted(set(parameters) - set(PAIR_PARAMETERS + SCALAR_PARAMETERS))
        if unknown:
            raise SceneError(f"{unknown[0]!r} cannot vary per arm; per-arm parameters: "
                             f"{', '.join(SCALAR_PARAMETERS + PAIR_PARAMETERS)}")
        if scene.method not in ("rk4", "exponential_rk4"):   # steps that run on arrays too
            raise SceneError(f"batch rollouts use rk4 or exponential_rk4, not {scene.method!r}")
        switching = [name for name in ("friction", "joint_limits") if getattr(scene, name)]
        if switching:
            raise SceneError(f"batch rollouts cannot run {' or '.join(switching)}: its switches "
                             "are located arm by arm (physics/switching/events.py); run such a scene "
                             "one arm at a time (arm-sim run)")
        if sampled := sampled_arm_by_arm(scene):
            raise SceneError(f"batch rollouts cannot run {sampled}; arm-sim run")
        if count is None:
            count = len(positions) if positions is not None else (
                len(velocities) if velocities is not None else 1)
        if count < 1:
            raise SceneError(f"a batch needs at least one arm, got {count}")
        self.scene, self.count, self.step_size = unestimated(scene), count, scene.step_size
        # Per-joint damping stays the scene's effect; per-arm damping is a scalar per arm.
        self._shared_damping = "damping" not in parameters
        scene_values = {name: getattr(scene, name) for name in PAIR_PARAMETERS + SCALAR_PARAMETERS}
        if isinstance(scene.damping, tuple):
            scene_values["damping"] = max(scene.damping)
        values = {name: _per_arm(name, parameters.get(name, scene_values[name]), count,
                                 name in PAIR_PARAMETERS)
                  for name in PAIR_PARAMETERS + SCALAR_PARAMETERS}
        self._check_physics(values)
        q0 = _per_arm("positions", scene.initial_positions if positions is None else positions,
                      count, True)
        qd0 = _per_arm("velocities", scene.initial_velocities if velocities is None else velocities,
                       count, True)
        self._build(scene, values, q0)
        self._initial = [np.array(q0[:, 0]), np.array(q0[:, 1]),
                         np.array(qd0[:, 0]), np.array(qd0[:, 1])]
        self.reset()

    @staticmethod
    def _check_physics(v: dict) -> None:
        """The checks of ArmParameters and Scene, arm by arm, vectorised."""
        _refuse_where(v["link_lengths"] <= 0, "link_lengths must be positive")
        _refuse_where(v["link_masses"] <= 0, "link_masses must be positive")
        _refuse_where(v["com_inertias"] < 0, "com_inertias must be non-negative")
        _refuse_where(v["gravity"] < 0, "gravity is a magnitude (along -y); it must be >= 0")
        _refuse_where(v["damping"] < 0, "damping would add energy; it must be >= 0")
        a, b, d = _arm_arrays(v).inertia_coefficients
        _refuse_where(~(a * d - d * d - b * b > 1e-12 * a * d),
                      "the mass matrix becomes singular at some elbow angle")

    def _build(self, scene: Scene, v: dict, q0: np.ndarray) -> None:
        # The source's structure (which effects exist) from the scene, switched on where
        # any arm needs an effect; its constants then become per-arm arrays.
        gravity_on = 1.0 if (v["gravity"] != 0).any() else 0.0
        damping = scene.damping if self._shared_damping else (
            1.0 if (v["damping"] != 0).any() else 0.0)
        structure = scene.replace(gravity=gravity_on, damping=damping)
        dynamics = build_dynamics(structure)
        self.channels, self.extra = dynamics.channels, dynamics.extra
        arm = _arm_arrays(v, structure)
        a, b, d, m22 = arm.mass_constants
        constants = {"A": a, "B": b, "TWO_B": 2.0 * b, "D": d, "M22": m22}
        # Each effect's own constants, from per-arm values where they vary per arm.
        per_arm = {"gravity": Gravity(v["gravity"])}
        if not self._shared_damping:
            per_arm["damping"] = Damping(v["damping"])
        for effect in dynamics.active:
            constants.update(per_arm.get(effect.name, effect).constants(arm))
        # The gravity torque the compensating policies believe, per arm (the structure's
        # placeholder gravity must not leak into the controller's model).
        k1, k2, gravity = _believed_gravity(scene, v, arm)
        if "GC1" in constants:
            constants["GC1"], constants["GC2"] = gravity * k1, gravity * k2
        if scene.policy == "constant":
            constants["TORQUE1"], constants["TORQUE2"] = v["constant_torque"].T
        elif scene.policy == "frozen_gravity":
            # g(q0) per arm, as model.gravity_torque computes it for one arm.
            g2 = gravity * k2 * np.cos(q0[:, 0] + q0[:, 1])
            constants["TORQUE1"], constants["TORQUE2"] = gravity * k1 * np.cos(q0[:, 0]) + g2, g2
        constants.pop("command", None)
        self.command = [np.zeros(self.count), np.zeros(self.count)]
        self._setpoint = _servo_setpoint(scene, constants.pop("SP", None), q0)
        # A constant shared by every arm stays a float: scalar * array is the cheaper loop.
        self._constants = {k: _shared_or_array(c, self.count) for k, c in constants.items()}
        self._namespace = dict(dynamics.function.__globals__, cos=np.cos, sin=np.sin,
                               MIN=np.minimum, MAX=np.maximum)
        self._code = compile(dynamics.source, f"<batch rhs {scene.policy}>", "exec")
        self._step = step_for(INTEGRATORS[scene.method], len(self.channels), dynamics.decay)
        self.substeps = self._worst_substeps(scene, v, arm)
        self._kernel = None
        if compiled.compilable(dynamics, self._step):   # every arm in one compiled call
            source, self._names = compiled.module_source(dynamics, self._step)
            self._kernel = compiled.load(source)

    @property
    def path(self) -> str:
        """Which code steps the arms: "compiled (numba)" or "numpy"."""
        return "compiled (numba)" if self._kernel is not None else "numpy"

    def _run_compiled(self, steps: int, threads: int) -> None:
        """Every arm `steps` steps in one compiled call, arms split over `threads`."""
        numba = compiled.numba
        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
        values = dict(self._namespace, **getattr(self._step, "constants", {}), **self._constants)
        columns = [*self.command, *(np.broadcast_to(values[k], (self.count,)) for k in self._names)]
        parameters = np.ascontiguousarray(np.stack(columns, axis=1), dtype=float)
        state = np.array(self.state)
        self._kernel.advance_batch(state, self.step_size / self.substeps,
                                   steps * self.substeps, parameters)
        self.state = list(state)

    def _worst_substeps(self, scene: Scene, v: dict, arm) -> int:
        """The single-arm stability plan of the stiffest arm. Every effect's stiffness grows
        with Lambda (the largest eigenvalue of M^-1 over all elbow angles) and with damping,
        so the arm with the largest Lambda, given the largest damping, bounds them all; it is
        each arm's own plan when the arms share their links or their damping."""
        a, b, d, m22 = arm.mass_constants
        worst = 0.0
        for c in (1.0, -1.0):                       # full extension and full fold
            m11, m12 = a + 2.0 * b * c, d + b * c
            inverse = stability.inverse_mass_eigenvalue(m11, m12, m22, np.hypot)
            worst = np.maximum(worst, np.broadcast_to(inverse, (self.count,)))
        i = int(np.argmax(worst))
        stiffest = scene.replace(**{name: tuple(v[name][i]) for name in LINK_PARAMETERS})
        if not self._shared_damping:
            stiffest = stiffest.replace(damping=float(v["damping"].max()))
        return Simulator(unestimated(stiffest)).substeps

    def reset(self) -> None:
        self.state = [a.copy() for a in self._initial] + [
            np.zeros(self.count) for _ in self.extra + self.channels]
        self.steps = 0

    @property
    def time(self) -> float:
        return self.steps * self.step_size

    @property
    def positions(self) -> np.ndarray:
        return np.stack(self.state[0:2], axis=1)

    @property
    def velocities(self) -> np.ndarray:
        return np.stack(self.state[2:4], axis=1)

    def channel(self, name: str) -> np.ndarray:
        """Per-arm value of a channel so far (zeros for work or dissipated energy when the
        effect is absent)."""
        if name in self.channels:
            return self.state[4 + len(self.extra) + self.channels.index(name)]
        if name not in ("work", "dissipated"):
            raise KeyError(name)
        return np.zeros(self.count)

    def set_command(self, tau1, tau2) -> None:
        """Torque held by the `command` policies: scalars or one value per arm."""
        self.command = [_per_arm("command", t, self.count, False) for t in (tau1, tau2)]

    def _rhs_for(self, chunk: slice):
        namespace = dict(self._namespace, command=[c[chunk] for c in self.command],
                         SP=[c if isinstance(c, float) else c[chunk] for c in self._setpoint],
                         **{k: c if isinstance(c, float) else c[chunk]
                            for k, c in self._constants.items()})
        exec(self._code, namespace)
        return namespace["rhs"]

    def _advance_chunk(self, chunk: slice, steps: int) -> None:
        f, step, h = self._rhs_for(chunk), self._step, self.step_size / self.substeps
        y = tuple(a[chunk] for a in self.state)
        for _ in range(steps * self.substeps):
            y = step(f, y, h)
        for target, value in zip(self.state, y):
            target[chunk] = value

    def run(self, steps: int, threads: int = 1) -> None:
        """Advance every arm by `steps` steps of the scene's method."""
        if steps < 0:
            raise SceneError(f"steps = {steps} must not be negative")
        if self._kernel is not None:
            self._run_compiled(steps, threads)
            self.steps += steps
            return
        chunks = [slice(s, min(s + CHUNK, self.count)) for s in range(0, self.count, CHUNK)]
        if threads > 1 and len(chunks) > 1:
            with ThreadPoolExecutor(threads) as pool:
                list(pool.map(lambda c: self._advance_chunk(c, steps), chunks))
        else:
            for chunk in chunks:
                self._advance_chunk(chunk, steps)
        self.steps += steps


def _shared_or_array(value, count: int):
    array = np.broadcast_to(np.asarray(value, dtype=float), (count,))
    return float(array[0]) if (array == array[0]).all() else np.ascontiguousarray(array)


class _ArmArrays(SimpleNamespace):
    """Per-arm link parameters with ArmParameters' own coefficient formulas, on arrays."""

    inertia_coefficients = property(ArmParameters.inertia_coefficients.fget)
    gravity_coefficients = property(ArmParameters.gravity_coefficients.fget)
    mass_constants = property(ArmParameters.mass_constants.fget)


def _arm_arrays(v: dict, scene: Scene | None = None, payload: float = 0.0) -> _ArmArrays:
    """The per-arm links, with the scene's payload (or `payload`) folded in and its motors'
    armature."""
    links = {name: (v[name][:, 0], v[name][:, 1]) for name in LINK_PARAMETERS}
    armature = (0.0, 0.0)
    if scene is not None and scene.payload is not None:
        payload = scene.payload["mass"]
    if (scene is not None and scene.payload is not None) or payload != 0.0:
        folded = fold_payload(links["link_lengths"][1], links["link_masses"][1],
                              links["com_distances"][1], links["com_inertias"][1], payload)
        for name, value in zip(("link_masses", "com_distances", "com_inertias"), folded):
            links[name] = (links[name][0], value)
    if scene is not None and scene.motors is not None:
        armature = scene.arm.armature
    return _ArmArrays(**links, armature=armature)


def _believed_gravity(scene: Scene, v: dict, arm: _ArmArrays):
    """(k1, k2, gravity) per arm of the gravity torque the compensating policies believe:
    the controller model's named values (effects/controller_model.py), each arm's own for
    the rest."""
    believed = scene.controller_model
    if believed is None:
        return (*arm.gravity_coefficients, v["gravity"])
    named = {name: np.broadcast_to(np.asarray(believed[name], dtype=float), v[name].shape)
             for name in ("link_lengths", "link_masses", "com_distances")
             if believed.get(name) is not None}
    payload = believed.get("payload_mass")
    if payload is None:
        payload = scene.payload["mass"] if scene.payload is not None else 0.0
    gravity = v["gravity"] if believed.get("gravity") is None else believed["gravity"]
    return (*_arm_arrays(v | named, payload=payload).gravity_coefficients, gravity)


PROGRESS_PARTS = 100      # a long batch reports its progress this many times


def throughput(scene: Scene, count: int, steps: int, threads: int = 1, seed: int = 0,
               progress=None) -> dict:
    """Arms around the scene's initial pose (uniform +-0.5 rad), timed; with a spot check of
    three arms against the single-arm simulator. `progress(steps done)` is called in
    between PROGRESS_PARTS parts of the run when given."""
    rng = np.random.default_rng(seed)
    positions = np.asarray(scene.initial_positions) + rng.uniform(-0.5, 0.5, (count, 2))
    batch = Batch(scene, positions, count=count)
    part = max(1, steps // PROGRESS_PARTS) if progress is not None else max(steps, 1)
    batch.run(0, threads)          # compiled path: compiled (or loaded from its cache) here
    start = time.perf_counter()
    for done in range(0, steps, part):
        batch.run(min(part, steps - done), threads)
        if progress is not None:
            progress(min(done + part, steps))
    elapsed = time.perf_counter() - start
    worst = 0.0
    for i in sorted({0, count // 2, count - 1}):
        sim = Simulator(unestimated(scene).replace(initial_positions=tuple(positions[i])))
        for _ in range(steps):
            sim.step()
        worst = max(worst, float(np.max(np.abs(np.array(sim.state[:4]) -
                                               np.array([a[i] for a in batch.state[:4]])))))
    finite = np.isfinite(np.stack(batch.state)).all(axis=0)
    return {"arms": count, "steps": steps, "threads": threads, "seconds": elapsed,
            "arm_steps_per_s": count * steps / elapsed, "non_finite_arms": int((~finite).sum()),
            "max_diff_vs_single_arm": worst}


def unestimated(scene: Scene) -> Scene:
    """`scene` as a batch steps it: the planned steps alone, no error estimate (estimate off,
    tolerance 0), as the single-arm simulator then takes them too."""
    return scene.replace(estimate="off", tolerance=0.0)


def _servo_setpoint(scene, setpoint, q0) -> list:
    """The servo's set-points (effects/servo.py): a joint holding its initial pose holds each
    arm's own; the scene's `setpoint` is every arm's. [] without a servo."""
    if setpoint is None:
        return []
    setpoint = [float(v) for v in setpoint]
    for i, kind in enumerate(scene.servo["interface"]):
        if not (scene.policy == "setpoint" and kind == "position"):
            setpoint[i] = q0[:, i]
    return setpoint
