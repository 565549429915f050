"""The `arm_sim` node without a transport: parameters, timer stepping, commands, JointState
and diagnostics. The rclpy and dds transports call into this; it imports neither.

Time: each tick advances exactly `steps_per_tick` RK4 steps of `step_size`, so simulated time
is always steps x step_size whether ticks come early, late or as fast as possible. Stamps are
the wall time at start plus simulated time, so a recording's stamps advance by exactly
1/publish_rate. The command timeout is measured on the simulation clock (deterministic, and
the same as wall time at real_time_factor 1).
"""
from __future__ import annotations

import time
from math import isfinite

from ..interface import COMMAND_TOPIC, ERROR, NODE_NAME, OK, WARN
from ..physics.simulator import Simulator
from .diagnostics import COUNTERS, DiagnosticData, JointStateData, diagnostic_values
from .parameters import SCENE_PARAMETERS, SPECS, NodeConfig

COMMAND_POLICIES = ("command", "command_gravity_compensation")
# Steps collected before the recorder gets them in one call: 0.1 s behind at the default one
# step a tick; collecting 50 measured slower than 10 (the kept states fall out of cache).
RECORD_EVERY = 10
WARN_PERIOD = 1.0                 # seconds between repeated warnings of one kind


class RateLimitedLog:
    """At most one line per kind per WARN_PERIOD; the next says how many were held back."""

    def __init__(self, log, clock=time.monotonic):
        self.log, self.clock = log, clock
        self._last, self._held = {}, {}

    def warning(self, kind: str, text: str) -> None:
        now = self.clock()
        last = self._last.get(kind)
        if last is not None and now - last < WARN_PERIOD:
            self._held[kind] = self._held.get(kind, 0) + 1
            return
        held = self._held.pop(kind, 0)
        self._last[kind] = now
        self.log.warning(text + (f" ({held} more like this since the last warning)" if held else ""))


# --- the node's behaviour -----------------------------------------------------------------------

class ArmSimCore:
    """Simulator + command handling + message assembly; transports call in, never the reverse."""

    def __init__(self, config: NodeConfig, log, wall_clock=time.monotonic,
                 start_stamp_ns: int | None = None, recorder=None):
        self.log = log
        self.wall_clock = wall_clock
        self.warnings = RateLimitedLog(log, wall_clock)
        self.start_stamp_ns = time.time_ns() if start_stamp_ns is None else start_stamp_ns
        self.received_commands = 0
        self.refused_commands = 0
        self.late_ticks = 0
        self.command_timeouts = 0
        self.recorder = None
        self._unrecorded = []             # states of steps the recorder has not seen yet
        self._elapsed_before_reset_ns = 0
        self._configure(config)
        self._attach(recorder if recorder is not None else self._make_recorder())
        self._event(f"scene {self.config.scene.name} started: policy {self.config.scene.policy}, "
                    f"h = {self.config.scene.step_size:g} s, {self.config.steps_per_tick} steps per tick")

    # configuration ---------------------------------------------------------------------------

    def _configure(self, config: NodeConfig) -> None:
        self.config = config
        self.sim = Simulator(config.scene)
        for event in self.sim.events:     # e.g. sub-stepping chosen while it was built
            self.log.info(event.message)
        self.listens = config.scene.policy in COMMAND_POLICIES
        self.command = (0.0, 0.0)
        self.command_received_at = None     # simulated time of the last good command
        self.held = False                   # integration left the finite numbers; holding
        self.max_abs_residual = 0.0
        self._last_tick_wall = None
        self._diag_wall = self.wall_clock()
        self._diag_time = self.sim.time
        self._refused_at_last_diag = self.refused_commands
        self._late_at_last_diag = self.late_ticks

    def set_parameters(self, changes: dict) -> list:
        """Apply runtime parameter changes; ParameterRefused leaves everything as it was.
        Returns the names whose value changed. A change to the physics restarts the scene."""
        config = self.config.with_changes(changes)
        changed = [n for n in SPECS if config.values[n] != self.config.values[n]]
        if any(n in SCENE_PARAMETERS for n in changed):
            self._restart(config, f"parameters {', '.join(changed)} changed: scene restarted "
                                  "from its initial state")
        else:
            self.config = config
        if any(n.startswith("rerun_") for n in changed):
            self.finish()
            self._attach(self._make_recorder())
        return changed

    def _make_recorder(self):
        if not self.config.telemetry_enabled:
            return None
        v = self.config.values
        try:
            from ..recording.telemetry import make_recorder  # heavy (rerun); only when asked for
            return make_recorder(self.config.scene, path=v["rerun_path"] or None,
                                 spawn=v["rerun_spawn"], connect=v["rerun_connect"] or None,
                                 warn=self.log.warning)
        except Exception as error:  # telemetry must never stop the simulation
            self.log.error(f"Rerun telemetry is off: {error}")
            return None

    def _attach(self, recorder) -> None:
        self.recorder = recorder
        self._call_recorder("start", self.sim)

    def _call_recorder(self, method: str, *args) -> None:
        if self.recorder is None:
            return
        if self._unrecorded and method != "step_batch":
            self._hand_over()             # the steps first, then what came after them
        try:
            getattr(self.recorder, method)(*args)
        except Exception as error:  # a failing sink is dropped, the simulation goes on
            self.log.error(f"Rerun telemetry failed in {method}() and is now off: {error}")
            self.recorder = None

    def _event(self, text: str) -> None:
        self.log.info(text)
        self._call_recorder("event", text)

    # commands --------------------------------------------------------------------------------

    def on_command(self, data) -> str | None:
        """Take [tau1, tau2] from joint_torque_commands; returns the refusal reason, if any."""
        self.received_commands += 1
        reason = self._refusal(data)
        if reason is not None:
            self.refused_commands += 1
            self.warnings.warning("refused", f"refused torque command: {reason}; holding "
                                  f"{list(self.command)} (refused so far: {self.refused_commands})")
            self._call_recorder("event", f"refused command: {reason}")
            return reason
        if not self.listens:
            self.warnings.warning("ignored", f"policy {self.config.scene.policy!r} ignores "
                                  f"{COMMAND_TOPIC}; set policy to command to drive the arm")
            return None
        if self.command_received_at is None:
            self.log.info(f"torque command {list(data)} N m, held until the next one")
        self.command = (float(data[0]), float(data[1]))
        self.command_received_at = self.sim.time
        self._set_command(*self.command)
        return None

    def _set_command(self, tau1: float, tau2: float) -> None:
        """Hold a new command; the steps taken under the old one reach the recorder first."""
        self._hand_over()
        self.sim.set_command(tau1, tau2)

    def _refusal(self, data) -> str | None:
        try:
            values = [float(v) for v in data]
        except (TypeError, ValueError):
            return f"data {data!r} is not a list of numbers"
        if len(values) != 2:
            return f"data has {len(values)} values; expected 2 ([tau1, tau2] in N m)"
        for i, tau in enumerate(values):
            if not isfinite(tau):
                return f"tau{i + 1} = {tau} is not finite"
        limit = self.config.values["torque_limit"]
        for i, tau in enumerate(values):
            if abs(tau) > limit:
                return f"|tau{i + 1}| = {abs(tau):g} N m exceeds torque_limit {limit:g} N m"
        return None

    def _check_timeout(self) -> None:
        timeout = self.config.values["command_timeout"]
        if (timeout > 0 and self.command_received_at is not None
                and self.sim.time - self.command_received_at >= timeout - 1e-12):
            self.command_received_at = None
            self.command_timeouts += 1
            if self.command != (0.0, 0.0):
                self.command = (0.0, 0.0)
                self._set_command(0.0, 0.0)
                self.log.warning(f"no torque command for {timeout:g} s: torque dropped to zero")
                self._call_recorder("event", "command timeout: torque dropped to zero")

    # stepping ---------------------------------------------------------------------------------

    def tick(self, wall_now: float | None = None) -> JointStateData:
        """One timer tick: steps_per_tick RK4 steps, then the JointState to publish."""
        self._note_lateness(self.wall_clock() if wall_now is None else wall_now)
        if not self.held:
            self._check_timeout()
            self._advance()
        return self.joint_state()

    def _note_lateness(self, wall_now: float) -> None:
        period = self.config.wall_period
        last, self._last_tick_wall = self._last_tick_wall, wall_now
        if period > 0 and last is not None and wall_now - last > 1.5 * period:
            self.late_ticks += 1

    def _advance(self) -> None:
        sim = self.sim
        before = (sim.state, sim.steps)
        self._step_recorded(sim, self.config.steps_per_tick)
        if sim.holding or not all(isfinite(v) for v in sim.state):
            # The simulator refused a step that would leave the finite numbers; hold the
            # whole tick so joint_states never carries a non-finite number.
            self._hand_over()
            sim.state, sim.steps = before
            self.held = True
            self.log.error(f"{sim.fault or 'integration cannot stay finite'} (at t = "
                           f"{sim.time:.6f} s); holding until reset")
            self._call_recorder("event", "integration not finite: holding")
            return
        self.max_abs_residual = max(self.max_abs_residual, abs(sim.residual()))

    def _step_recorded(self, sim, steps: int) -> None:
        """`steps` physics steps, each seen by the recorder: their states collected and
        handed over in one step_batch(sim, states) call per RECORD_EVERY steps when it has
        one (a Python call per step, or per tick at one step a tick, costs more than
        logging's 10 % budget), else step(sim) after every step. Anything else sent to the
        recorder, a new command or a restart hands the collected steps over first."""
        advance, recorder = sim.step, self.recorder
        if recorder is None:
            for _ in range(steps):
                advance()
        elif hasattr(recorder, "step_batch"):
            keep = self._unrecorded.append
            for _ in range(steps):
                advance()
                keep(sim.state)
            if len(self._unrecorded) >= RECORD_EVERY:
                self._hand_over()
        else:
            for _ in range(steps):
                advance()
                self._call_recorder("step", sim)

    def _hand_over(self) -> None:
        states, self._unrecorded = self._unrecorded, []
        if states:
            self._call_recorder("step_batch", self.sim, states)

    def _step_ns(self) -> int:
        return round(self.sim.step_size * 1e9)

    def stamp_ns(self) -> int:
        return self.start_stamp_ns + self._elapsed_before_reset_ns + self.sim.steps * self._step_ns()

    def joint_state(self) -> JointStateData:
        y = self.sim.state
        tau = self.sim.dynamics.applied_torque((y[0], y[1]))
        return JointStateData(self.stamp_ns(), self.config.values["frame_id"],
                              self.config.values["joint_names"], [y[0], y[1]], [y[2], y[3]],
                              [float(tau[0]), float(tau[1])])

    def reset(self) -> None:
        """Back to the scene's initial state; stamps keep increasing."""
        self._restart(self.config, "reset to the scene's initial state")

    def _restart(self, config: NodeConfig, why: str) -> None:
        self._hand_over()                 # they belong to the simulator about to go
        self._elapsed_before_reset_ns += self.sim.steps * self._step_ns()
        self._configure(config)
        self._call_recorder("start", self.sim)
        self._event(why)

    def finish(self) -> None:
        self._call_recorder("finish", self.sim)
        self.recorder = None

    # diagnostics ------------------------------------------------------------------------------

    def real_time_factor(self, wall_now: float) -> float:
        wall = wall_now - self._diag_wall
        return (self.sim.time - self._diag_time) / wall if wall > 0 else 0.0

    def diagnostics(self, wall_now: float | None = None) -> DiagnosticData:
        """The 1 Hz status: refused commands, real-time factor, energy residual, late ticks,
        sub-steps and refused steps.
        Rates are over the interval since the previous call."""
        wall_now = self.wall_clock() if wall_now is None else wall_now
        rtf = self.real_time_factor(wall_now)
        new_refused = self.refused_commands - self._refused_at_last_diag
        new_late = self.late_ticks - self._late_at_last_diag
        self._diag_wall, self._diag_time = wall_now, self.sim.time
        self._refused_at_last_diag, self._late_at_last_diag = self.refused_commands, self.late_ticks
        if self.held:
            level, message = ERROR, "integration not finite: holding the last finite state"
        elif new_refused or new_late:
            level, message = WARN, f"{new_refused} refused commands, {new_late} late ticks in the last interval"
        else:
            level, message = OK, "running"
        values = diagnostic_values(self.sim, f"{rtf:.3f}", self.max_abs_residual, self.held,
                                   self.command, self.config.steps_per_tick,
                                   {name: getattr(self, name) for name in COUNTERS})
        return DiagnosticData(self.stamp_ns(), level, f"{NODE_NAME}: simulation", message,
                              NODE_NAME, values)

    def status_line(self, rtf: float) -> str:
        """The one-line status the node prints each second."""
        residual = "held" if self.held else f"{self.sim.residual():+.2e} J"
        return (f"t = {self.sim.time:9.3f} s   real-time factor {rtf:6.2f}   energy residual "
                f"{residual}   refused commands {self.refused_commands}")
