"""The `arm_sim` node without a transport: timer stepping, JointState and diagnostics, over
the parameters (parameters.py), the command intake (commands.py) and the recorder
(recorder_link.py). The rclpy and dds transports call into this; it imports neither.

Time: each tick advances exactly `steps_per_tick` RK4 steps of `step_size`, so simulated time
is always steps x step_size whether ticks come early, late or as fast as possible. Stamps (and
/clock) are an origin plus simulated time, so they advance by exactly 1/publish_rate: the
origin is 0 (`clock_origin` zero, as Gazebo's /clock) or the wall clock at start (wall).
"""
from __future__ import annotations

import time
from math import isfinite

from ..interface import NODE_NAME
from ..physics.effects import servo
from ..physics.model import angle_warning
from ..physics.scene import load_scene
from ..physics.urdf.read import changed_values, read_urdf
from ..physics.simulator import Simulator, abs_residual
from .commands.callbacks import CommandInput
from .commands.intake import CommandIntake, RateLimitedLog
from .diagnostics import COUNTERS, DiagnosticData, JointStateData, diagnostic_values
from .params.parameters import LIVE, SCENE_PARAMETERS, SPECS, NodeConfig
from .params.rebuild import build_simulator, change_live
from .recorder_link import RecorderLink, make_recorder
from .schedule import Lockstep
from .status import Console, Interval, health, what_is_on


class ArmSimCore(CommandInput, Console):
    """Simulator + command handling + message assembly; transports call in, never the reverse."""

    def __init__(self, config: NodeConfig, log, wall_clock=time.monotonic,
                 start_stamp_ns: int | None = None, recorder=None):
        self.log, self.wall_clock = log, wall_clock
        self.start_stamp_ns = clock_origin_ns(config, start_stamp_ns)
        self.warnings = RateLimitedLog(log, wall_clock)
        self.commands = CommandIntake(log, self.warnings)
        self.late_ticks = 0
        self.lockstep = Lockstep()        # which command answers which state
        self.paused = False               # no physics; the held state is published (simulation.py)
        self._elapsed_before_reset_ns = 0
        self._configure(config)
        self.recorder = RecorderLink(log, recorder if recorder is not None
                                     else make_recorder(config, log), self.sim,
                                     stamp_origin_ns=self.start_stamp_ns)
        self._event(started(config, recording=self.recorder.recorder is not None))
        if warning := angle_warning(config.scene.initial_positions, node=True):
            log.warning(warning)

    received_commands = property(lambda self: self.commands.received)
    refused_commands = property(lambda self: self.commands.refused)
    command_timeouts = property(lambda self: self.commands.timeouts)
    command = property(lambda self: self.commands.value)
    stale_commands = property(lambda self: self.lockstep.stale)

    def _configure(self, config: NodeConfig, sim: Simulator | None = None) -> None:
        """`config` with `sim` (default: built now) from its initial state."""
        self.sim = build_simulator(config, config.given or ("scene",)) if sim is None else sim
        self.config = config
        for event in self.sim.events:     # e.g. sub-stepping chosen while it was built
            self.log.info(event.message)
        self.sim.event_listeners.append(self._on_sim_event)
        self.commands.restart()
        self.held = False                   # integration left the finite numbers; holding
        self.published = Published()        # the JointStates, the last finite one kept
        self.max_abs_residual = 0.0
        self._last_tick_wall = None
        self.interval = Interval(self.wall_clock(), self.sim.time, self.refused_commands,
                                 self.late_ticks)
        if config.values["lockstep"]:     # the state the first command answers
            self.lockstep.queue(self.joint_state())

    def _on_sim_event(self, event) -> None:
        """Said at the event's level as it happens (a fault: _advance), warnings rate-limited."""
        text = f"{event.message} (at t = {event.t:.6f} s)"
        if event.level == "warning":
            self.warnings.warning(event.kind, text)
        elif event.kind != "fault":
            (self.log.info if event.level == "info" else self.log.error)(text)

    def set_parameters(self, changes: dict) -> list:
        """Runtime parameter changes as one transaction (rebuild.py): the new physics built
        and checked aside, then swapped in; ParameterRefused (the physical reason) leaves
        config, simulator and recording as they were. Returns the names whose value changed.
        A change to the arm, the policy or the integration restarts the scene; one to a live
        effect (LIVE) carries on from now; one to rerun_* closes the recording, opens anew."""
        config = self.config.with_changes(changes)
        changed = [n for n in SPECS if config.values[n] != self.config.values[n]]
        restart = any(n in SCENE_PARAMETERS and n not in LIVE for n in changed)
        # what reset would build must build: a value that cannot is refused here, not later
        sim = build_simulator(config, changed) if restart or set(changed) & set(LIVE) else None
        if restart:
            self._restart(config, f"parameters {', '.join(changed)} changed: scene restarted "
                                  "from its initial state", sim)
        else:
            self._change_physics(config, [n for n in changed if n in LIVE])
        if any(n.startswith("rerun_") for n in changed):
            self.recorder = self.recorder.reopen(config)
        if "lockstep" in changed and config.values["lockstep"] and not restart:
            self.lockstep.queue(self.joint_state())      # switched on: answer this state
        return changed

    def _event(self, text: str) -> None:
        self.log.info(text)
        self.recorder.event(text)

    def _set_command(self, tau1: float, tau2: float, setpoints=None) -> None:
        """Hold a new command; the steps taken under the old one reach the recorder first."""
        self.recorder.hand_over()
        self.sim.set_command(tau1, tau2, setpoints)

    def _change_physics(self, config: NodeConfig, names: list) -> None:
        """Live effects changed: the new physics from the next step, state and books carried
        over (rebuild.change_live); the steps before reach the recorder first, and it
        learns the new channels."""
        self.recorder.hand_over()
        if names:          # the transaction (rebuild.py); a servo switches bumplessly
            change_live(self.sim, config, names)
            self.commands.value = tuple(self.sim.dynamics.given)
        self.config = config
        if names:
            self.recorder.start(self.sim)
            self._event(live_change(names, config.values, self.sim.time))

    def tick(self, wall_now: float | None = None,
             clock_listened: bool = False) -> JointStateData | None:
        """One timer tick: steps_per_tick RK4 steps, then the JointState to publish. In
        lockstep the answers tick (callbacks.py): None, unless a node listens on /clock
        (`clock_listened`: a use_sim_time peer, which may wait for the clock to move before
        it commands) and no tick came for lockstep_wait. Paused: the held state."""
        if self.paused or not self.config.values["lockstep"]:   # lockstep: each state once
            return (None if self.config.values["lockstep"] else self.joint_state()) \
                if self.paused else self._tick(wall_now)
        wait = self.config.values["lockstep_wait"] if clock_listened else 0.0
        now = self.wall_clock() if wall_now is None else wall_now
        last = self._last_tick_wall
        return self.lockstep.latest(self._tick(now)) if wait and (
            last is None or now - last >= wait) else None

    def step_tick(self) -> JointStateData:
        """A tick now (StepSimulation; in lockstep once answered: SimulationControl.ready)."""
        self._last_tick_wall = None       # asked for: not late
        data = self._tick()
        return self.lockstep.latest(data) if self.config.values["lockstep"] else data

    def _tick(self, wall_now: float | None = None) -> JointStateData:
        self._note_lateness(self.wall_clock() if wall_now is None else wall_now)
        if not self.held:
            if self.commands.timed_out(self.sim.time, self.config.values["command_timeout"]):
                self._set_command(0.0, 0.0)
                servo.hold(self.sim.dynamics, self.sim.readings)   # where it reads it is
                self.recorder.event("command timeout: torque dropped to zero", "warn")
            self._advance()
        else:       # held: the state stands still, time does not (stamps, /clock, --duration)
            self.sim.steps += self.config.steps_per_tick
        if self.interval.waiting:         # the status's pace counts from the first tick done
            self.first_tick_done()
        return self.joint_state()

    def _note_lateness(self, wall_now: float) -> None:
        period = self.config.wall_period
        last, self._last_tick_wall = self._last_tick_wall, wall_now
        if period > 0 and last is not None and wall_now - last > 1.5 * period:
            self.late_ticks += 0 if self.config.values["lockstep"] else 1   # commands tick it

    def _advance(self) -> None:
        sim = self.sim
        before = (sim.state, sim.steps)
        self.recorder.step(self.config.steps_per_tick, self._last_tick_wall, self.late_ticks)
        total = sum(sim.state)          # finite: every value is (inf - inf, NaN are NaN)
        if sim.holding or (total - total != 0.0 and not all(isfinite(v) for v in sim.state)):
            # The simulator refused a step that would leave the finite numbers; hold the whole
            # tick's state (never a non-finite number), its time going on as refused steps do
            self.recorder.hand_over()
            sim.state, sim.steps = before[0], before[1] + self.config.steps_per_tick
            return self._hold(sim.fault or "integration cannot stay finite",
                              "integration not finite: holding")
        residual = abs_residual(sim)    # the divergence check's, computed once
        if residual > self.max_abs_residual:      # as max() keeps it, NaN included
            self.max_abs_residual = residual

    def _hold(self, why: str, event: str) -> None:
        self.held = True
        self.log.error(f"{why} (at t = {self.sim.time:.6f} s); holding until reset")
        self.recorder.event(event, "error")

    def stamp_ns(self) -> int:
        return self.start_stamp_ns + self._elapsed_before_reset_ns + self.sim.steps * round(self.sim.step_size * 1e9)

    def joint_state(self) -> JointStateData:
        """The JointState now (Published.joint_state): positions, velocities and the torque
        the joints receive, or the readings beside the truth; always finite."""
        data, finite = self.published.joint_state(self.sim, self.config.values, self.stamp_ns())
        if not (finite or self.held):   # a reading or torque past the doubles: held, said
            self._hold("a reading or torque is beyond double precision; holding the last "
                       "finite message", "readings not finite: holding")
        return data

    def reset(self) -> None:       # back to the initial state; stamps keep increasing
        self._restart(self.config, "reset to the scene's initial state")

    def _restart(self, config: NodeConfig, why: str, sim: Simulator | None = None) -> None:
        self.recorder.hand_over()         # they belong to the simulator about to go
        self._elapsed_before_reset_ns += self.sim.steps * round(self.sim.step_size * 1e9)
        self._configure(config, sim)
        self.recorder.start(self.sim)
        self._event(why)

    def finish(self) -> None:
        self.log.info(self.stop_line(self.recorder.finish()))    # the recording closed first

    def real_time_factor(self, wall_now: float) -> float:
        return self.interval.real_time_factor(wall_now, self.sim.time)

    def diagnostics(self, wall_now: float | None = None) -> DiagnosticData:
        """The 1 Hz status (diagnostics.py); rates over the interval since the previous call."""
        wall_now = self.wall_clock() if wall_now is None else wall_now
        rtf, new_refused, new_late = self.interval.close(wall_now, self.sim.time,
                                                         self.refused_commands, self.late_ticks)
        level, message = health(self.held, new_refused, new_late, self.sim.books_fault)
        values = diagnostic_values(self.sim, f"{rtf:.3f}", self.max_abs_residual, self.held,
                                   self.command, self.config.steps_per_tick,
                                   {name: getattr(self, name) for name in COUNTERS},
                                   self.commands.last_refusal)
        return DiagnosticData(self.stamp_ns(), level, f"{NODE_NAME}: simulation", message,
                              NODE_NAME, values)


class Published:
    """The JointStates a node publishes, and the last of them whose numbers were all finite:
    what it publishes, at the stamp of the moment, where a reading or torque leaves the
    doubles at a finite state (a scene's start is finite: physics/trust/guard.check_start)."""

    def __init__(self):
        self.last = None

    def joint_state(self, sim, values: dict, stamp_ns: int) -> tuple[JointStateData, bool]:
        """(the JointState of `sim` now, whether its numbers are finite; if not, the last
        one that was). Positions, velocities and the torque the joints receive (after
        gearing, windings and effort limits: what a joint torque sensor would read). With
        `sensors`, positions and velocities are the readings (physics/sensing/), and `truth`
        the state itself, same stamp (~/true_joint_states)."""
        y, tau = sim.state, sim.joint_torque(sim.state)
        data = truth = JointStateData(stamp_ns, values["frame_id"], values["joint_names"],
                                      [y[0], y[1]], [y[2], y[3]], [float(tau[0]), float(tau[1])])
        if sim.scene.sensors is not None:
            r = sim.readings
            data = truth._replace(position=[r[0], r[1]], velocity=[r[2], r[3]], truth=truth)
        if all(isfinite(v) for part in (data, truth) for v in part.position + part.velocity
               + part.effort):
            self.last = data
            return data, True
        truth = self.last.truth and self.last.truth._replace(stamp_ns=stamp_ns)
        return self.last._replace(stamp_ns=stamp_ns, truth=truth), False


def started(config: NodeConfig, recording: bool = True) -> str:
    """The start line: the scene, its step and method, and what is on (status.what_is_on:
    the estimate, sensors and where the truth goes, command latency, lockstep, the recording,
    named only where `recording` is under way; scripts/run names a new file each run); with a
    robot_description, every scene value the URDF replaced."""
    scene, values = config.scene, config.values
    text = (f"scene {scene.name} started: policy {scene.policy}, h = {scene.step_size:g} s, "
            f"{scene.method}, {config.steps_per_tick} steps per tick; "
            + "; ".join(what_is_on(scene, values, recording)))
    if values["robot_description"]:
        base = load_scene(values["scene"])
        changed = changed_values(base, read_urdf(values["robot_description"]).scene(base))
        text += f"; robot_description replaced: {'; '.join(changed) or 'nothing'}"
    return text


def clock_origin_ns(config: NodeConfig, given: int | None) -> int:
    """What stamps and /clock count from: a given origin (a transport's clock, a test's fixed
    one), else 0 (clock_origin zero) or the wall clock now (wall)."""
    if given is not None:
        return given
    return time.time_ns() if config.values["clock_origin"] == "wall" else 0


def live_change(names: list, values: dict, t: float) -> str:
    """The log line of a live change: what changed, to what, and when."""
    what = ", ".join(f"{name} -> {values[name]}" for name in names)
    booked = "; the payload's energy is booked in payload_exchange" if "payload.mass" in names else ""
    return f"{what} at t = {t:.6f} s: the motion carries on from the current state{booked}"
