"""`arm-sim run ... --bag DIR`: the topics the node would have published, from an offline run.

JointState every publish period (header stamps: simulated time from 0, as the node's with
clock_origin zero; with sensors the readings, and the truth on /arm_sim/true_joint_states
at the same stamps), the applied command when the policy takes commands, and the node's
diagnostics every simulated second. The bag's own clock (each message's receive time, what
`ros2 bag info` shows) is the wall clock when the run started plus simulated time, as
`ros2 bag record` of the node would have written it, so the bag does not start in 1970; written through recording.bag's BagWriter, so the bag opens even after a kill -9
(losing at most its last CHUNK_SECONDS of wall time) and a full disk closes it with what fit.
The last diagnostics say how the run ended: finished, stopped early (and by what, when the
caller sets `stop_reason`), or holding after a fault.
"""
from __future__ import annotations

from math import ceil, isfinite
from pathlib import Path
from time import perf_counter, time_ns

from ...interface import ERROR, NODE_TOPICS, OK, SENSOR_TOPICS, TRUE_JOINT_STATES, WARN
from ...node.core import diagnostic_values
from ...node.params.parameters import steps_per_tick
from ...node.params.values import ParameterRefused
from ...recording.bags.bag import (BagError, BagWriter, diagnostic_array, joint_state,
                                   torque_command)
from ..arguments import scene_from_args

DIAGNOSTICS_PERIOD = 1.0  # s of simulated time, as the node's 1 Hz diagnostics timer


def steps_per_publish(step_size: float, publish_rate: float) -> int:
    """Integration steps between two publications, by the node's own rule: a rate whose
    period is not a whole number of steps is refused (stamps must stay simulated time)."""
    if not (isfinite(publish_rate) and publish_rate > 0):
        raise BagError(f"--publish-rate {publish_rate} must be a positive number of Hz")
    try:
        return steps_per_tick(publish_rate, step_size)
    except ParameterRefused as error:
        raise BagError(f"--publish-rate {error.reason}") from None


def nanoseconds(sim) -> int:
    """Simulated time in ns, from the step count (never an accumulated float)."""
    return round(sim.steps * sim.step_size * 1e9)


# Policies whose torque is a command: what the offline run applied is recorded as one.
APPLIED_COMMAND_POLICIES = ("constant", "command", "command_gravity_compensation")


class RunBag:
    """A recorder for `arm-sim run`: JointState every publish period (stamped with
    simulated time; bag time is the run's wall start + simulated time), the applied command alongside it when the
    policy takes commands, and diagnostics every simulated second (and at the end)."""

    def __init__(self, path, publish_steps: int):
        self.path = path
        self.publish_steps = publish_steps
        self.writer = None
        self.stop_reason = None   # what stopped the run early (a signal's name), if the caller knows

    def start(self, sim) -> None:
        self.bag_origin_ns = time_ns() - nanoseconds(sim)   # bag time = this + simulated time
        self.writer = BagWriter(self.path, start_ns=self.bag_origin_ns)
        self.end_steps = sim.steps + sim.scene.steps_for(sim.scene.duration, sim.step_size)
        self.commands = sim.scene.policy in APPLIED_COMMAND_POLICIES
        self.sensors = sim.scene.sensors is not None
        for topic, msgtype in (NODE_TOPICS | (SENSOR_TOPICS if self.sensors else {})).items():
            if self.commands or topic != "/joint_torque_commands":
                self.writer.add_topic(topic, msgtype)
        self.diagnostics_steps = ceil(DIAGNOSTICS_PERIOD / sim.step_size - 1e-9)
        self.last_diagnostics = 0
        self.max_abs_residual = 0.0
        self.wall_start = perf_counter()
        self.publish(sim)

    def step(self, sim) -> None:
        if sim.steps % self.publish_steps == 0:
            self.publish(sim)
        if (sim.steps - self.last_diagnostics >= self.diagnostics_steps
                and sim.steps < self.end_steps):      # the last one, at the end, says how it ended
            self.diagnose(sim)

    def finish(self, sim) -> None:
        if self.writer is None or self.writer.failed:   # never started, or closed by a failure
            return
        try:
            self.diagnose(sim, ending=True)
        finally:
            self.writer.close()

    def publish(self, sim) -> None:
        s, t = sim.sample(), nanoseconds(sim)
        if not sim.holding:  # the largest |residual| at a tick, as the node keeps it
            self.max_abs_residual = max(self.max_abs_residual, abs(s.residual))
        at = self.bag_origin_ns + t
        if self.sensors:      # the readings as the node publishes them, the truth beside
            self.writer.write("/joint_states", at, joint_state(t, s.measured[:2],
                                                               s.measured[2:], s.tau))
            self.writer.write(TRUE_JOINT_STATES, at, joint_state(t, s.q, s.qd, s.tau))
        else:
            self.writer.write("/joint_states", at, joint_state(t, s.q, s.qd, s.tau))
        if self.commands:
            self.writer.write("/joint_torque_commands", at, torque_command(applied_command(sim)))

    def diagnose(self, sim, ending: bool = False) -> None:
        """The node's diagnostics, same keys; an offline run refuses and misses nothing."""
        t, wall = nanoseconds(sim), perf_counter() - self.wall_start
        command = applied_command(sim) if self.commands else (0.0, 0.0)
        # A refused (non-finite) step leaves the last finite state in place, as in the node.
        level, message = ((ERROR, sim.fault) if sim.holding else self.ending(sim) if ending
                          else (OK, "running"))
        values = diagnostic_values(sim, f"{sim.time / wall:.3f}" if wall > 0 else "inf",
                                   self.max_abs_residual, sim.holding, command, self.publish_steps)
        self.writer.write("/diagnostics", self.bag_origin_ns + t, diagnostic_array(t, message, level=level, values=values))
        self.last_diagnostics = sim.steps

    def ending(self, sim) -> tuple[int, str]:
        """How the run ended, for its last diagnostics."""
        planned = sim.scene.duration
        if sim.steps >= self.end_steps:
            return OK, f"finished: ran its {planned:g} s"
        by = f" by {self.stop_reason}" if self.stop_reason else ""
        return WARN, f"stopped{by} at t = {sim.time:.6f} s, before the end of its {planned:g} s"


def applied_command(sim):
    """The command part of the torque: the constant torque, or the held command."""
    scene = sim.scene
    return scene.constant_torque if scene.policy == "constant" else tuple(sim.dynamics.given)


def run_recorder(args):
    """RUN_RECORDERS hook: a RunBag for `--bag DIR`, refused before the run if the rate
    does not divide the step or DIR exists."""
    steps = steps_per_publish(scene_from_args(args, note=lambda line: None).step_size,  # said once
                              args.publish_rate)
    if Path(args.bag).exists():
        raise BagError(f"--bag {args.bag} exists already; a recording never overwrites one")
    return RunBag(args.bag, steps)
