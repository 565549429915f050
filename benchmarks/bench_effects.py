"""µs per RK4 step for each effect alone and all together, beside the effect-free arm and
beside MuJoCo's RK4 on the same arm with the same options, timed in the same run.

Every row is the `release` preset (gravity, released from horizontal rest) at h = 1e-3 s
with one effect added. Ours is timed as bench_core times it (`Simulator.step`), MuJoCo's
as bench_peers builds and steps it (`mj_step` through the Python bindings, one call per
step; hinges about z, no contacts); each keeps the fastest of --repeat runs of --steps
steps. The runs go in rounds, every row (ours, then MuJoCo's) once per round in an order
rotated from round to round, so that a noisy moment slows all rows alike. The last row is
the geared_arm preset itself. The effects in MuJoCo's own terms are mujoco_peer's (the
table in arm_sim_ros/tools/accuracy/mujoco_peer.py's docstring); the effort-limit rows ask a constant
torque above the limits (both simulators clamp it), and controller_model is ours only.

Agreement: both simulators run the row's scene for 1 s at h = 1e-3 from the same state;
the table gives the largest |q_ours - q_mujoco| and |qd_ours - qd_mujoco| at any step,
beside how far the row's effects move the arm from the effect-free run (so a small gap is
not small because nothing happened). Where the windings are on, the gap is MuJoCo's
first-order current update; the run ends with both simulators against a DOP853 reference.

--before DIR also times the effect-free step of the tree before the effects (a checkout of
dc76dfe, flat layout) in a worker process, once per round, for "costs what it did":

    pip install .[bench]
    git worktree add /tmp/before dc76dfe        # only for --before
    nice python benchmarks/bench_effects.py [--steps 1000] [--repeat 30] [--before /tmp/before]
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # the sibling benchmark scripts

from bench_core import TreeWorker, fastest, time_simulator  # noqa: E402  (best of repeats)

from arm_sim_ros.physics import model as arm_model  # noqa: E402
from arm_sim_ros.physics.effects import Motors  # noqa: E402
from arm_sim_ros.physics.scene import load_scene  # noqa: E402
from arm_sim_ros.physics.simulator import Simulator  # noqa: E402
from arm_sim_ros.tools.accuracy import mujoco_peer  # noqa: E402
from arm_sim_ros.tools.accuracy.mujoco_peer import mujoco_data, reset  # noqa: E402

STEP = 1e-3              # s: the windings' L/R is 0.53 ms, so h must be this small
CHECK_SECONDS = 1.0      # agreement run

# The maxon EC 45 flat 70 W through 100:1 and 50:1 gears (figures: config/scenes/geared_arm.yaml).
GEARS = {"gear_ratio": (100.0, 50.0), "rotor_inertia": (1.81e-5, 1.81e-5)}
WINDINGS = GEARS | {"resistance": (0.573, 0.573), "inductance": (0.301e-3, 0.301e-3),
                    "torque_constant": (0.0404, 0.0404)}
# 2 V instead of the real 24 V supply so that the voltage clamp binds in the all-together rows.
WINDINGS_LIMITED = WINDINGS | {"voltage_limit": (2.0, 2.0)}
DAMPING = (0.5, 0.2)
SPRINGS = {"stiffness": (20.0, 10.0), "rest_positions": (0.3, -0.2)}
PAYLOAD = {"mass": 0.5}
ABOVE_LIMIT = {"policy": "constant", "constant_torque": (30.0, 15.0)}   # asks more than...
LIMITS = (15.0, 10.0)                                                  # ...the joints allow
MUJOCO_MODELLED = {"damping": DAMPING, "springs": SPRINGS, "payload": PAYLOAD,
                   "motors": GEARS, "effort_limits": LIMITS, **ABOVE_LIMIT}


@dataclass
class Row:
    label: str
    overrides: dict = field(default_factory=dict)
    preset: str = "release"


ROWS = [
    Row("effect-free arm (release: gravity only)"),
    Row("damping [0.5, 0.2]", {"damping": DAMPING}),
    Row("springs k [20, 10], rest [0.3, -0.2]", {"springs": SPRINGS}),
    Row("payload 0.5 kg", {"payload": PAYLOAD}),
    Row("motors: armature N^2 J (100:1, 50:1)", {"motors": GEARS}),
    Row("constant torque [30, 15] (actuator)", dict(ABOVE_LIMIT)),
    Row("effort limits [15, 10] (+ torque above)", {"effort_limits": LIMITS, **ABOVE_LIMIT}),
    Row("motors: windings (zero policy: 0 V)", {"motors": WINDINGS}),
    Row("gravity_compensation policy (actuator)", {"policy": "gravity_compensation"}),
    Row("controller_model (+ gravity_comp.)", {"policy": "gravity_compensation",
                                                "controller_model": {"payload_mass": 0.5}}),
    Row("all together (MuJoCo-modelled effects)", dict(MUJOCO_MODELLED)),
    Row("all together (+ windings, 2 V limit)", MUJOCO_MODELLED | {"motors": WINDINGS_LIMITED}),
    Row("all together (+ windings, controller_model)",
        MUJOCO_MODELLED | {"motors": WINDINGS_LIMITED, "policy": "gravity_compensation",
                           "controller_model": {"payload_mass": 0.3}}),
    Row("geared_arm preset as shipped (24 V)", preset="geared_arm"),
]


# ---------------------------------------------------------------- MuJoCo's side

def mujoco_model(scene):
    """(MjModel, ctrl) of the scene with its effects in MuJoCo's terms (RK4), or (None, why)
    where MuJoCo has no counterpart for one of them (arm_sim_ros.tools.accuracy.mujoco_peer)."""
    try:
        return mujoco_peer.mujoco_model(scene, "RK4")
    except mujoco_peer.Unsupported as error:
        return None, str(error).split(" (")[0]


def time_mujoco(model, scene, ctrl, steps: int, repeat: int) -> float:
    """µs per mj_step, fastest of `repeat` runs (the reset is ~1 µs per run, not per step)."""
    import mujoco

    step, data = mujoco.mj_step, mujoco_data(model, scene, ctrl)

    def run():
        reset(model, data, scene, ctrl)
        for _ in range(steps):
            step(model, data)
    return fastest(run, repeat) / steps * 1e6


def agreement(scene, model, ctrl, seconds: float) -> tuple[float, float]:
    """Largest |Δq|, |Δqd| between ours and MuJoCo's RK4 at any step of `seconds`."""
    import mujoco

    sim, data = Simulator(scene), mujoco_data(model, scene, ctrl)
    dq = dqd = 0.0
    for _ in range(scene.steps_for(seconds)):
        sim.step()
        mujoco.mj_step(model, data)
        s = sim.state
        dq = max(dq, abs(s[0] - data.qpos[0]), abs(s[1] - data.qpos[1]))
        dqd = max(dqd, abs(s[2] - data.qvel[0]), abs(s[3] - data.qvel[1]))
    return dq, dqd


def effect_size(scene, free_scene, seconds: float) -> float:
    """Largest |q - q_effect-free| (ours) at any step of `seconds`: how much the row's effects
    move the arm, so that a small gap to MuJoCo is not small because nothing happened."""
    sim, free = Simulator(scene), Simulator(free_scene)
    gap = 0.0
    for _ in range(scene.steps_for(seconds)):
        sim.step()
        free.step()
        gap = max(gap, abs(sim.state[0] - free.state[0]), abs(sim.state[1] - free.state[1]))
    return gap


# ---------------------------------------------------------------- the windings' reference

def windings_reference(scene, seconds: float):
    """q at `seconds` from scipy's DOP853 (rtol = atol = 1e-12) on the windings written out
    from model.forward_dynamics (not our generated code): L di/dt = V - R i - k N qd,
    joint torque k N i, V = clamp(R a / (N k), +-Vlim) for the (constant) requested a."""
    from scipy.integrate import solve_ivp

    motors = Motors(**scene.motors)
    arm, gravity = scene.arm, scene.gravity
    damping = scene.damping if isinstance(scene.damping, tuple) else (scene.damping,) * 2
    asked = scene.constant_torque if scene.policy == "constant" else (0.0, 0.0)
    if scene.effort_limits is not None:
        asked = tuple(min(max(t, -e), e) for t, e in zip(asked, scene.effort_limits))
    volts = []
    for i in (0, 1):
        v = motors.resistance[i] * asked[i] / (motors.gear_ratio[i] * motors.torque_constant[i])
        if motors.voltage_limit is not None:
            v = min(max(v, -motors.voltage_limit[i]), motors.voltage_limit[i])
        volts.append(v)
    kn = [k * n for k, n in zip(motors.torque_constant, motors.gear_ratio)]

    def rates(t, y):
        q, qd, current = y[0:2], y[2:4], y[4:6]
        torque = [kn[i] * current[i] for i in (0, 1)]
        if scene.springs is not None:
            (k1, k2), (r1, r2) = scene.springs["stiffness"], scene.springs["rest_positions"]
            torque = [torque[0] - k1 * (q[0] - r1), torque[1] - k2 * (q[1] - r2)]
        torque = [torque[i] - damping[i] * qd[i] for i in (0, 1)]
        qdd = arm_model.forward_dynamics(arm, q, qd, torque, gravity)
        di = [(volts[i] - motors.resistance[i] * current[i] - kn[i] * qd[i])
              / motors.inductance[i] for i in (0, 1)]
        return [qd[0], qd[1], qdd[0], qdd[1], di[0], di[1]]

    y0 = [*scene.initial_positions, *scene.initial_velocities, 0.0, 0.0]
    solution = solve_ivp(rates, (0.0, seconds), y0, method="DOP853", rtol=1e-12, atol=1e-12)
    return solution.y[0:2, -1]


def windings_convergence(scene, seconds: float = 0.2, steps=(1e-3, 1e-4, 1e-5)) -> list[str]:
    """Ours and MuJoCo's dcmotor against the reference at several h: who carries the gap."""
    import mujoco

    reference = windings_reference(scene, seconds)
    lines = [f"windings: |q - reference| at t = {seconds:g} s (DOP853 on the winding equations "
             "written from model.forward_dynamics)",
             f"{'h (s)':>8} {'ours sub-steps':>14} {'ours':>10} {'MuJoCo dcmotor RK4':>19}",
             "-" * 54]
    for h in steps:
        at_h = scene.replace(step_size=h)
        n = at_h.steps_for(seconds)
        sim = Simulator(at_h)
        for _ in range(n):
            sim.step()
        model, ctrl = mujoco_model(at_h)
        data = mujoco_data(model, at_h, ctrl)
        for _ in range(n):
            mujoco.mj_step(model, data)
        ours = max(abs(sim.state[i] - reference[i]) for i in (0, 1))
        theirs = max(abs(data.qpos[i] - reference[i]) for i in (0, 1))
        lines.append(f"{h:>8g} {sim.substeps:>14d} {ours:>10.1e} {theirs:>19.1e}")
    return lines


# ---------------------------------------------------------------- the tree before the effects

BEFORE_WORKER = r"""
import sys, time
import arm_sim_ros
from arm_sim_ros.scene import load_scene
from arm_sim_ros.simulator import Simulator
steps, h = int(sys.argv[1]), float(sys.argv[2])
base = load_scene("release").replace(step_size=h)
scenes = [base, base.replace(damping=0.5)]
print(arm_sim_ros.__file__, flush=True)
for _ in sys.stdin:
    times = []
    for scene in scenes:
        sim = Simulator(scene)
        step = sim.step
        start = time.perf_counter()
        for _ in range(steps):
            step()
        times.append((time.perf_counter() - start) / steps * 1e6)
    print(*times, flush=True)
"""
BEFORE_ROWS = ("effect-free arm (release)", "damping 0.5 (one value for both joints)")


class BeforeTree(TreeWorker):
    """The pre-effects source tree (flat layout: arm_sim_ros.scene, arm_sim_ros.simulator) in a
    worker process; each run() is one timed run of --steps steps per BEFORE_ROWS scene,
    interleaved with ours."""

    def __init__(self, tree: Path, steps: int):
        super().__init__(tree, BEFORE_WORKER, str(steps), repr(STEP))


# ---------------------------------------------------------------- the table

def has_windings(scene) -> bool:
    return scene.motors is not None and Motors(**scene.motors).windings


def scene_of(row: Row, base):
    if row.preset == "release":
        return base.replace(**row.overrides)
    return load_scene(row.preset).replace(step_size=STEP, duration=CHECK_SECONDS, tolerance=0.0,
                                          **row.overrides)


def measure(rows, base, steps: int, repeat: int, before: BeforeTree | None):
    """`repeat` rounds; each round times every row once, ours and MuJoCo's back to back (and
    the tree before the effects), in an order rotated from round to round, so that a noisy
    moment hits all rows alike instead of one row's runs; each keeps its fastest run.
    Returns ours with damping 0.5 (timed only beside --before) and the rows' results."""
    free_scene, damped_scene = scene_of(rows[0], base), base.replace(damping=0.5)
    scenes = [scene_of(row, base) for row in rows]
    models = [mujoco_model(scene) for scene in scenes]
    ours, theirs, damped_us = [float("inf")] * len(rows), [float("inf")] * len(rows), float("inf")
    slots = list(range(len(rows))) + (["before", "damped"] if before is not None else [])
    for round_ in range(repeat):
        for slot in slots[round_ % len(slots):] + slots[:round_ % len(slots)]:
            if slot == "before":
                before.run()
            elif slot == "damped":
                damped_us = min(damped_us, time_simulator(damped_scene, steps, 1))
            else:
                ours[slot] = min(ours[slot], time_simulator(scenes[slot], steps, 1))
                model, ctrl = models[slot]
                if model is not None:
                    theirs[slot] = min(theirs[slot],
                                       time_mujoco(model, scenes[slot], ctrl, steps, 1))
    results = []
    for row, scene, (model, ctrl), ours_us, mujoco_us in zip(rows, scenes, models, ours, theirs):
        gaps = agreement(scene, model, ctrl, CHECK_SECONDS) if model is not None else None
        moved = effect_size(scene, free_scene, CHECK_SECONDS) if row is not rows[0] else None
        results.append((row, scene, ours_us, mujoco_us if model is not None else None,
                        gaps, moved, None if model is not None else ctrl))
    return damped_us, results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000, help="steps per timed run")
    parser.add_argument("--repeat", type=int, default=30, help="timed runs; the fastest counts")
    parser.add_argument("--before", type=Path, metavar="DIR",
                        help="a checkout of the tree before the effects (e.g. a git worktree of "
                             "dc76dfe): time its effect-free step in the same run")
    args = parser.parse_args()
    try:
        import mujoco
    except ImportError:
        sys.exit("bench_effects needs MuJoCo: pip install .[bench] (mujoco==4.0.0)")

    started = time.perf_counter()
    # tolerance 0: the scheme alone, so that ours and MuJoCo's RK4 take the same steps
    base = load_scene("release").replace(step_size=STEP, duration=CHECK_SECONDS, tolerance=0.0)
    before = BeforeTree(args.before, args.steps) if args.before is not None else None
    try:
        damped_us, results = measure(ROWS, base, args.steps, args.repeat, before)
        free_us = results[0][2]
    finally:
        if before is not None:
            before.close()
    print(f"µs per step of h = {STEP:g} s (RK4), fastest of {args.repeat} runs of {args.steps} "
          f"steps; ours = Simulator.step, MuJoCo {mujoco.__version__} = mj_step (RK4)")
    print(f"max |Δq|, |Δqd| = largest gap between ours and MuJoCo at any step of a "
          f"{CHECK_SECONDS:g} s run from the row's initial state;\neffect |Δq| = largest gap "
          f"between the row and the effect-free arm (ours) in the same run\n")
    header = (f"{'effect':<44} {'sub-steps':>9} {'ours µs':>8} {'÷ free':>7} {'MuJoCo µs':>10} "
              f"{'MuJoCo ÷ ours':>13} {'max |Δq|':>9} {'max |Δqd|':>9} {'effect |Δq|':>11}")
    print(header)
    print("-" * len(header))
    not_modelled = []
    for row, scene, ours_us, mujoco_us, gaps, moved, why in results:
        if mujoco_us is None:
            not_modelled += [why] if why not in not_modelled else []
            theirs = f"{'n/a':>10} {'':>13} {'n/a':>9} {'n/a':>9}"
        else:
            mark = "†" if has_windings(scene) else " "
            theirs = (f"{mujoco_us:>10.2f} {mujoco_us / ours_us:>13.2f} {gaps[0]:>8.1e}{mark} "
                      f"{gaps[1]:>8.1e}{mark}")
        moved = f"{'—':>11}" if moved is None else f"{moved:>11.1e}"
        print(f"{row.label:<44} {Simulator(scene).substeps:>9d} {ours_us:>8.2f} "
              f"{ours_us / free_us:>7.2f} {theirs} {moved}")

    print("\nall together = damping + springs + payload + armature + effort limits with the "
          "constant torque\n  above them; + windings: their R, L, k with a 2 V driver limit "
          "(it binds); + controller_model:\n  gravity_compensation believing a 0.3 kg payload "
          "(0.5 kg held) instead of the constant torque.\n  geared_arm: the preset itself "
          "(damping 0.05, 0.3 kg, the maxon motors at 24 V, effort limits,\n  "
          "command_gravity_compensation).")
    print("sub-steps: RK4 sub-steps our simulator takes per step to keep the windings "
          "(L/R = 0.53 ms)\n  stable (Simulator.substeps); MuJoCo takes one mj_step per step "
          "in every row.")
    print(f"n/a: not built in MuJoCo here: {', '.join(not_modelled)}.\n  Ours recomputes "
          "the policy's torque, and the controller's believed g(q), at every RK stage;\n  "
          "MuJoCo's ctrl is held over a step (its body gravcomp would compensate the true g "
          "exactly,\n  never a controller's wrong model).")
    print("†: MuJoCo 4.0.0 does model windings (the dcmotor actuator: current state, L, R, k, "
          "back-EMF;\n  it forces actearly), but its RK4 advances the current by the RK4-weighted "
          "mean of the four stage\n  slopes times τ(1 - e^(-h/τ)), τ = L/R (the filterexact "
          "step), instead of times h. That is\n  h(1 - h/2τ + ...): an O(h²) error in the "
          "current every step, so MuJoCo is first order in h\n  there, and the gap is MuJoCo's "
          "integration error, not a model difference. Below, against an\n  independent "
          "reference, MuJoCo's error falls 10x per 10x smaller h, ours stays at 1e-14 or below:\n")
    for label in ("motors: windings (zero policy: 0 V)", "all together (+ windings, 2 V limit)"):
        row = next(r for r in ROWS if r.label == label)
        print(f"{label}:")
        print("\n".join(windings_convergence(scene_of(row, base))) + "\n")
    if before is not None:
        print(f"before the effects ({args.before}) and now, the same release scene at h = "
              f"{STEP:g} s, interleaved, fastest of {args.repeat} runs:")
        for label, then, now in zip(BEFORE_ROWS, before.best, (free_us, damped_us)):
            print(f"  {label:<42} before {then:6.2f} µs   now {now:6.2f} µs   "
                  f"now ÷ before {now / then:5.2f}")
    print(f"\ntotal run time {time.perf_counter() - started:.0f} s")


if __name__ == "__main__":
    main()
