"""The scene's arm in MuJoCo, with its effects in MuJoCo's own terms, for side-by-side runs.

The arm: hinges about z, gravity along -y, each rod's inertia given explicitly (COM inertia
about z from the scene, about the rod axis tiny but non-zero so that the body is valid), no
contacts. Built this way MuJoCo's RK4 reproduces our rk4 to ~1e-14. The effects:

    damping: d or [d1, d2]          joint damping
    springs: {stiffness, rest_pos.}  joint stiffness + springref
    payload: {mass: m}               a body of mass m (no inertia) at the tip of link 2
    motors: {gear_ratio, rotor_in.}  joint armature N^2 J
    motors windings (R, L, k, Vlim)  dcmotor actuators; MuJoCo's current update is first
                                     order (bench_effects.py shows it)
    constant policy, effort_limits   motor actuators, ctrl = the torque, forcerange = limits
    gravity_compensation policy      body gravcomp (exact while no limit clamps it)
    friction: {coulomb}              frictionloss = coulomb: a soft constraint, Coulomb only
                                     (no breakaway above it, no Stribeck curve)
    joint_limits hard (e)            range, MuJoCo's soft limit with damping ratio
                                     ζ = -ln e / √(π² + ln² e): a damped contact's rebound
    joint_limits compliant (k, c)    range, solref = (-k/I, -c/I), I = the joint's inertia
                                     at the initial pose: MuJoCo's limit is an acceleration-
                                     level constraint, so the spring is matched only there

Friction and limits are soft constraints in MuJoCo, and the state follows their law, not
ours: its error against the reference stops falling with h (an error floor).
"""
from __future__ import annotations

from contextlib import contextmanager
from math import log, pi, sqrt

from ...physics import model as arm_model
from ...physics.effects import Motors

AXIAL_INERTIA = 1e-9     # about the rod axis: physically ~0 for a thin rod, must be > 0
JOINTS = ("link1_joint", "link2_joint")
INTEGRATORS = ("Euler", "implicit", "implicitfast", "RK4")
SOFT = ("friction", "joint_limits")     # MuJoCo constraints: their own (soft) law
UNSTABLE = (3, 4, 5)    # mjtWarning: mjWARN_BADQPOS, mjWARN_BADQVEL, mjWARN_BADQACC


class Unsupported(ValueError):
    """The scene uses something this peer cannot express in MuJoCo."""


def available() -> str | None:
    """None when `import mujoco` works, else why not (one line)."""
    try:
        import mujoco  # noqa: F401
    except ImportError as error:
        return f"MuJoCo is not installed ({error.msg}): pip install '.[bench]'"
    return None


def version() -> str:
    import mujoco
    return mujoco.__version__


def mjcf(scene) -> str:
    """MJCF for the scene's bare arm: its links, step and gravity, no effects (spec_of adds
    them)."""
    (l1, l2), (m1, m2), (r1, r2), (i1, i2) = (scene.link_lengths, scene.link_masses,
                                              scene.com_distances, scene.com_inertias)

    def link(name, length, mass, com, inertia, child=""):
        return (f'<body name="{name}"><joint name="{name}_joint" type="hinge" axis="0 0 1"/>'
                f'<geom type="capsule" fromto="0 0 0 {length!r} 0 0" size="0.02" contype="0" '
                f'conaffinity="0"/>'
                f'<inertial pos="{com!r} 0 0" mass="{mass!r}" '
                f'diaginertia="{AXIAL_INERTIA!r} {inertia!r} {inertia!r}"/>{child}</body>')

    inner = link("link2", l2, m2, r2, i2).replace('<body name="link2"',
                                                   f'<body name="link2" pos="{l1!r} 0 0"', 1)
    return (f'<mujoco model="arm_sim_ros"><option timestep="{scene.step_size!r}" '
            f'gravity="0 {-scene.gravity!r} 0"/>'
            f'<worldbody>{link("link1", l1, m1, r1, i1, inner)}</worldbody></mujoco>')


def check(scene) -> list[str]:
    """What differs from ours, one phrase each; Unsupported where MuJoCo has no match."""
    if scene.controller_model is not None:
        raise Unsupported("controller_model (MuJoCo has no controller's own model of the arm)")
    if scene.policy not in ("zero", "constant", "gravity_compensation"):
        raise Unsupported(f"policy {scene.policy} (MuJoCo's ctrl is held over a step)")
    motors = Motors(**scene.motors) if scene.motors is not None else None
    windings = motors is not None and motors.windings
    if scene.policy == "gravity_compensation" and (scene.effort_limits or windings):
        raise Unsupported("gravity compensation through effort limits or windings "
                          "(MuJoCo's gravcomp is never clamped)")
    notes = []
    if windings:
        notes.append("windings: MuJoCo's dcmotor current update is first order in h")
    if scene.friction is not None:
        fr = scene.friction
        breakaway = fr.get("static") not in (None, fr["coulomb"]) or fr.get("stribeck_velocity")
        notes.append("friction: MuJoCo frictionloss (soft constraint)"
                     + (", Coulomb only: no breakaway or Stribeck curve" if breakaway else ""))
    if scene.joint_limits is not None:
        compliant = scene.joint_limits.get("stiffness") is not None
        notes.append("joint limits: MuJoCo's soft limit" + (
            ", k and c matched at the initial pose only" if compliant else
            ", restitution as its damping ratio (ours: an impulse)"))
    return notes


def spec_of(scene):
    """An MjSpec of the scene with its effects (see the module's table) and its ctrl
    (mujoco_model sets the integrator)."""
    import mujoco

    check(scene)
    spec = mujoco.MjSpec.from_string(mjcf(scene))
    spec.compiler.degree = False          # springref, range in radians (MJCF: degrees)
    joints = [spec.joint(name) for name in JOINTS]
    damping = scene.damping if isinstance(scene.damping, tuple) else (scene.damping,) * 2
    springs = scene.springs or {"stiffness": (0.0, 0.0), "rest_positions": (0.0, 0.0)}
    motors = Motors(**scene.motors) if scene.motors is not None else None
    inertia = joint_inertia(scene)
    for i, joint in enumerate(joints):
        joint.damping = [damping[i], 0.0, 0.0]            # (linear, quadratic, cubic)
        joint.stiffness = [springs["stiffness"][i], 0.0, 0.0]
        joint.springref = springs["rest_positions"][i]
        joint.armature = scene.arm.armature[i]          # the motors' N^2 J, else 0
        if scene.friction is not None:
            joint.frictionloss = scene.friction["coulomb"][i]
        limits = scene.joint_limits
        if limits is not None:
            joint.limited = mujoco.mjtLimited.mjLIMITED_TRUE
            joint.range = [limits["lower"][i], limits["upper"][i]]
            if limits.get("stiffness") is not None:
                joint.solref_limit = [-limits["stiffness"] / inertia[i],
                                      -(limits.get("damping") or 0.0) / inertia[i]]
            elif limits.get("restitution"):
                # A damped spring contact rebounds with e = exp(-ζπ/√(1-ζ²)) at any stiffness.
                e = log(limits["restitution"])
                joint.solref_limit = [joint.solref_limit[0], -e / sqrt(pi * pi + e * e)]
    if scene.payload is not None:
        tip = spec.body("link2").add_body(name="payload", pos=[scene.link_lengths[1], 0.0, 0.0])
        tip.explicitinertial = True
        tip.mass, tip.ipos, tip.inertia = scene.payload["mass"], [0.0, 0.0, 0.0], [0.0] * 3
    if scene.policy == "gravity_compensation":
        for body in spec.bodies[1:]:
            body.gravcomp = 1.0
    return spec, actuators(spec, scene, motors)


def joint_inertia(scene) -> tuple[float, float]:
    """Each joint's inertia 1/(M⁻¹)ᵢᵢ at the initial pose (scene.arm: payload and the
    motors' armature included)."""
    m11, m12, m22 = arm_model.mass_matrix(scene.arm, scene.initial_positions)
    det = m11 * m22 - m12 * m12
    return det / m22, det / m11


def actuators(spec, scene, motors) -> list[float]:
    """Motor (or dcmotor) actuators driving the policy's torque; their held ctrl."""
    import mujoco

    torque = scene.constant_torque if scene.policy == "constant" else (0.0, 0.0)
    ctrl = []
    if motors is not None and motors.windings:
        if scene.effort_limits is not None:   # ours clamps the request before the driver
            torque = tuple(min(max(t, -e), e) for t, e in zip(torque, scene.effort_limits))
        for i, name in enumerate(JOINTS):
            n, r = motors.gear_ratio[i], motors.resistance[i]
            inductance, k = motors.inductance[i], motors.torque_constant[i]
            actuator = spec.add_actuator(name=f"{name}_dcmotor", target=name,
                                         trntype=mujoco.mjtTrn.mjTRN_JOINT)
            actuator.set_to_dcmotor(motorconst=[k, k], resistance=r, inductance=[inductance, 0.0])
            actuator.gear[0] = n
            if motors.voltage_limit is not None:
                actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
                actuator.ctrlrange = [-motors.voltage_limit[i], motors.voltage_limit[i]]
            ctrl.append(r * torque[i] / (n * k))       # our driver's voltage, held
    elif scene.policy == "constant":
        for i, name in enumerate(JOINTS):
            actuator = spec.add_actuator(name=f"{name}_motor", target=name,
                                         trntype=mujoco.mjtTrn.mjTRN_JOINT)
            actuator.set_to_motor()
            if scene.effort_limits is not None:
                actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
                actuator.forcerange = [-scene.effort_limits[i], scene.effort_limits[i]]
            ctrl.append(torque[i])
    return ctrl


def mujoco_model(scene, integrator: str = "RK4"):
    """(MjModel, ctrl) of the scene at its step size with `integrator` (INTEGRATORS)."""
    import mujoco

    spec, ctrl = spec_of(scene)
    spec.option.timestep = scene.step_size
    spec.option.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{integrator.upper()}")
    return spec.compile(), ctrl


def mujoco_data(model, scene, ctrl):
    """MjData at the scene's initial state with the ctrl held."""
    import mujoco

    data = mujoco.MjData(model)
    reset(model, data, scene, ctrl)
    return data


def reset(model, data, scene, ctrl) -> None:
    import mujoco

    mujoco.mj_resetData(model, data)
    data.qpos[:] = scene.initial_positions
    data.qvel[:] = scene.initial_velocities
    data.ctrl[:] = ctrl


@contextmanager
def silenced():
    """MuJoCo's warnings off its stderr (a run it finds unstable is counted in data.warning,
    or seen as a restart, instead)."""
    import mujoco

    told = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda message: None)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(told)


class Runner:
    """One MuJoCo integrator at one step size: `run(total, every)` steps `total` times
    through mj_step (one Python call per step, as a user of its Python bindings steps it)
    and keeps (q1, q2, qd1, qd2) at the start and every `every`-th step; `go` is what is
    timed (the same)."""

    def __init__(self, scene, integrator: str):
        import mujoco

        self.scene, self.step = scene, mujoco.mj_step
        self.model, self.ctrl = mujoco_model(scene, integrator)
        self.data = mujoco_data(self.model, scene, self.ctrl)

    def run(self, total: int, every: int) -> list[tuple]:
        """The samples; after a step MuJoCo found unstable (it then restarts from the
        initial state) every later sample is infinitely wrong."""
        model, data, step = self.model, self.data, self.step
        reset(model, data, self.scene, self.ctrl)
        kept = [(*data.qpos, *data.qvel)]
        with silenced():
            warnings = [data.warning[w] for w in UNSTABLE]
            for n in range(1, total + 1):
                step(model, data)
                if n % every == 0:
                    if any(w.number for w in warnings):
                        break
                    kept.append((*data.qpos, *data.qvel))
        return kept + [(float("inf"),) * 4] * (total // every + 1 - len(kept))

    go = run


class Rollout(Runner):
    """The same through mujoco.rollout: every step in one call of its C loop, each state
    kept; `go` (timed) is that call."""

    def __init__(self, scene, integrator: str):
        import mujoco
        import numpy as np
        from mujoco import rollout

        super().__init__(scene, integrator)
        whole = mujoco.mjtState.mjSTATE_FULLPHYSICS
        self.initial = np.zeros(mujoco.mj_stateSize(self.model, whole))
        mujoco.mj_getState(self.model, self.data, self.initial, whole)
        self.control = np.array(self.ctrl, dtype=float).reshape(1, 1, -1) if self.ctrl else None
        self.rollout = rollout.rollout

    def go(self, total: int, every: int = 1):
        """States (time, qpos, qvel, ...) after each of `total` steps."""
        with silenced():
            return self.rollout(self.model, self.data, self.initial, self.control,
                                nstep=total)[0][0]

    def run(self, total: int, every: int) -> list[tuple]:
        """As Runner.run; a restart shows as time that does not advance (the full physics
        state begins with it)."""
        states, nq, nv = self.go(total), self.model.nq, self.model.nv
        kept, clock = [tuple(self.initial[1:1 + nq + nv])], self.initial[0]
        for n, row in enumerate(states, start=1):
            if not row[0] > clock:
                break
            clock = row[0]
            if n % every == 0:
                kept.append(tuple(row[1:1 + nq + nv]))
        return kept + [(float("inf"),) * 4] * (total // every + 1 - len(kept))
