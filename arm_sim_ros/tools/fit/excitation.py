"""`arm-sim excite DIR`: record an identification run offline, a multi-sine torque.

A good recording for `arm-sim fit` moves every joint through a band of frequencies, turns
it round often (friction shows at each reversal) and stays within the effort limits. A
multi-sine does: harmonics of 1/duration within a band (BAND Hz), the shoulder on the odd
ones and the elbow on the even ones (no frequency shared: the two inputs are
uncorrelated), Schroeder phases for a low crest factor, scaled to a peak per joint.

The run replays it through our Simulator (the scene's drive chain and physics, torque
held per sample) and writes a rosbag2 as the node would publish it: /joint_states (effort
= the applied torque) and /joint_torque_commands (the multi-sine), optionally with
Gaussian noise on the measured positions and velocities; a scene with `sensors` records
their readings, as the node publishes them. For a real arm, --torques writes
the same schedule as a CSV (t, tau1, tau2) for its controller to play, and the recording
of that run is what to fit.

Exit codes: 0 written; 1 the run cannot be a recording to fit (the simulation faulted: the
bag is removed; a joint never moved, or its recorded readings show none of its motion as a
fit reads them, beyond their noise: the bag is kept, the line says why); 2 bad input (one
line), such as a scene whose servos follow set-points and ignore the torque.
"""
from __future__ import annotations

import sys
from math import isfinite

import numpy as np

from ...interface import FLOAT64_MULTI_ARRAY, JOINT_NAMES, JOINT_STATE
from ...outputs import check_output, clear_output, write_text
from ...physics.scene import parse_value
from ..arguments import add_scene_arguments, scene_from_args
from .data import FitError, Recording

BAND = (0.1, 2.0)          # Hz
DEFAULT_PEAK = (5.0, 2.0)  # N m, without effort limits
LIMIT_SHARE = 0.8          # of the effort limits, with them


def multisine(duration: float, rate: float, peaks, band=BAND):
    """(t, tau (N, 2)): the excitation sampled at `rate` Hz, |tau_i| <= peaks[i]."""
    n = int(round(duration * rate)) + 1
    t = np.arange(n) / rate
    harmonics = [k for k in range(1, int(band[1] * duration) + 1) if k / duration >= band[0]]
    if len(harmonics) < 2:
        raise FitError(f"--duration {duration:g} s holds fewer than two harmonics in "
                       f"{band[0]:g}-{band[1]:g} Hz; record longer")
    tau = np.zeros((n, 2))
    for joint in (0, 1):
        mine = harmonics[joint::2]
        count = len(mine)
        for i, k in enumerate(mine):
            phase = -np.pi * i * (i + 1) / count          # Schroeder
            tau[:, joint] += np.cos(2 * np.pi * k / duration * t + phase)
        tau[:, joint] *= peaks[joint] / np.max(np.abs(tau[:, joint]))
    return t, tau


def record(scene, path, duration: float, rate: float, peaks, noise=(0.0, 0.0), seed: int = 0):
    """Run the multi-sine through our Simulator and write the bag at `path`: (the
    simulator, whether each joint moved, the Recording written: what a fit reads). It stops
    at a refused step (the simulator's fault says why: the caller removes the bag)."""
    from ...physics.simulator import Simulator
    from ...recording.bags.bag import BagWriter, joint_state, torque_command

    t, tau = multisine(duration, rate, peaks)
    substeps = max(1, int(np.ceil(1.0 / (rate * scene.step_size) - 1e-9)))
    policy = scene.policy if scene.policy.startswith("command") else "command"
    sim = Simulator(scene.replace(policy=policy, step_size=1.0 / (rate * substeps)))
    rng = np.random.default_rng(seed)
    start, moved, written = sim.state[:2], [False, False], []
    with BagWriter(path) as bag:
        bag.add_topic("/joint_states", JOINT_STATE)
        bag.add_topic("/joint_torque_commands", FLOAT64_MULTI_ARRAY)
        for k, (t1, t2) in enumerate(tau.tolist()):
            sim.set_command(t1, t2)
            ns = round(t[k] * 1e9)
            s = sim.sample()
            read = s.measured or (*s.q, *s.qd)      # with sensors: as the node publishes
            q = np.array(read[:2]) + rng.normal(0.0, noise[0], 2) if noise[0] else read[:2]
            qd = np.array(read[2:]) + rng.normal(0.0, noise[1], 2) if noise[1] else read[2:]
            bag.write("/joint_states", ns, joint_state(ns, q, qd, sim.joint_torque()))
            written.append((t[k], *q, *qd, *sim.joint_torque()))
            bag.write("/joint_torque_commands", ns, torque_command((t1, t2)))
            for _ in range(substeps):
                sim.step()
            if sim.fault is not None:
                break
            moved = [m or q != q0 for m, q, q0 in zip(moved, sim.state[:2], start)]
    rows = np.array(written, dtype=float).reshape(-1, 7)
    return sim, moved, Recording(str(path), rows[:, 0], rows[:, 1:3], rows[:, 3:5], rows[:, 5:])


def unread(recording) -> list[int]:
    """The joints whose recorded readings (position and velocity) move nowhere beyond
    EXPLAINED x their noise, as `arm-sim fit` reads them (stats.motion): a fit learns
    nothing of them, whatever the truth did (a sensor delay longer than the run, a
    resolution or a noise coarser than the motion). Fewer samples than a fit reads are not
    judged: the fit refuses them itself, and their 4th differences tell no noise."""
    from .bounds import EXPLAINED
    from .data import MIN_SAMPLES
    from .problem import noise_level
    from .stats import motion

    if len(recording) < MIN_SAMPLES:
        return []
    moves = motion(recording, noise_level(recording))
    return [j for j in (0, 1) if not max(moves[j], moves[2 + j]) > EXPLAINED]


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("excite", help="record a multi-sine identification run (offline bag)")
    p.add_argument("bag", metavar="DIR", help="the rosbag2 directory to write")
    add_scene_arguments(p)
    p.add_argument("--duration", default="10", help="seconds (default 10)")
    p.add_argument("--rate", type=float, default=500.0, help="JointState rate, Hz (default 500)")
    p.add_argument("--peak", metavar="TAU1,TAU2",
                   help=f"peak torque per joint, N m (default {LIMIT_SHARE:g} x the effort "
                        f"limits, else {DEFAULT_PEAK[0]:g},{DEFAULT_PEAK[1]:g})")
    p.add_argument("--noise", default="0,0", metavar="RAD,RAD_PER_S",
                   help="Gaussian noise on the recorded q and qd (default none)")
    p.add_argument("--seed", type=int, default=0, help="of the noise (a whole number >= 0)")
    p.add_argument("--torques", metavar="PATH.csv", help="also write the schedule t, tau1, tau2")
    p.add_argument("--force", action="store_true", help="replace existing outputs")
    p.set_defaults(func=cmd_excite)


def cmd_excite(args) -> int:
    scene = scene_from_args(args)
    duration = parse_value("duration", args.duration)
    if not (0 < duration <= 3600 and 1 <= args.rate <= 10_000):
        raise FitError("--duration must be 0-3600 s and --rate 1-10000 Hz")
    if args.peak is not None:
        peaks = parse_value("constant_torque", args.peak)
    elif scene.effort_limits is not None:
        peaks = tuple(LIMIT_SHARE * e for e in scene.effort_limits)
    else:
        peaks = DEFAULT_PEAK
    noise = parse_value("constant_torque", args.noise)
    if len(peaks) != 2 or not all(isfinite(p) and p > 0 for p in peaks):
        raise FitError(f"--peak {args.peak}: two positive, finite torques in N m")
    if len(noise) != 2 or not all(isfinite(n) and n >= 0 for n in noise):
        raise FitError(f"--noise {args.noise}: two finite numbers >= 0 (rad, rad/s)")
    if args.seed < 0:
        raise FitError(f"--seed {args.seed}: a whole number >= 0")
    if scene.effort_limits is not None and any(p > e for p, e in zip(peaks, scene.effort_limits)):
        raise FitError(f"--peak {list(peaks)} exceeds the effort limits {list(scene.effort_limits)}")
    deaf = [f"joint {i + 1} ({kind})" for i, kind in enumerate(
        (scene.servo or {}).get("interface", ("effort", "effort"))) if kind != "effort"]
    if deaf:
        raise FitError(f"scene {scene.name}: its servos follow set-points on {', '.join(deaf)} "
                       "and ignore the torque: the multi-sine would not move the arm (--set "
                       "servo.interface=effort,effort, or a scene without servos)")
    bag = check_output(args.bag, "bag", args.force, directory=True)
    torques = args.torques and check_output(args.torques, "--torques", args.force, suffixes=(".csv",))
    for path in (bag, torques):
        if path:
            clear_output(path)
    if torques:
        t, tau = multisine(duration, args.rate, peaks)
        write_text(torques, "t,tau1,tau2\n" + "".join(f"{a!r},{b!r},{c!r}\n" for a, b, c in
                                                     zip(t.tolist(), *tau.T.tolist())), "--torques")
    sim, moved, written = record(scene, bag, duration, args.rate, peaks, noise, args.seed)
    if sim.fault is not None:
        clear_output(bag)
        print(f"arm-sim: error: the simulation faulted, so no recording was written: "
              f"{sim.fault} (peaks {peaks[0]:g}, {peaks[1]:g} N m: lower --peak, or a finer "
              "--step)", file=sys.stderr)
        return 1
    print(f"wrote {bag}: {duration:g} s of a multi-sine at {args.rate:g} Hz, peaks "
          f"{peaks[0]:g}, {peaks[1]:g} N m; final q = ({sim.state[0]:.4f}, {sim.state[1]:.4f}) rad")
    still = [name for name, m in zip(JOINT_NAMES, moved) if not m]
    blind = [JOINT_NAMES[j] for j in unread(written) if moved[j]]
    said = ([f"{' and '.join(still)} never moved in {bag} (static friction or a limit holds "
             "it? raise --peak)"] if still else []) + (
        [f"the readings of {' and '.join(blind)} in {bag} show no motion beyond their noise "
         "(a sensors.delay longer than the run? a resolution or --noise coarser than the "
         "motion?)"] if blind else [])
    if said:
        print(f"arm-sim: error: {'; '.join(said)}: a fit learns nothing of it", file=sys.stderr)
        return 1
    return 0
