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
from dataclasses import dataclass
from math import isfinite

from .model import ParameterError
from .scene import FIELD_KINDS, Scene, SceneError, coerce_value, load_scene
from .simulator import Simulator

NODE_NAME = "arm_sim"
JOINT_STATES_TOPIC = "joint_states"
COMMAND_TOPIC = "joint_torque_commands"
DIAGNOSTICS_TOPIC = "/diagnostics"
COMMAND_POLICIES = ("command", "command_gravity_compensation")
MAX_STEPS_PER_TICK = 100_000      # beyond this one tick would freeze the node for seconds
# Steps collected before the recorder gets them in one call: 0.1 s behind at the default one
# step a tick; collecting 50 measured slower than 10 (the kept states fall out of cache).
RECORD_EVERY = 10
WARN_PERIOD = 1.0                 # seconds between repeated warnings of one kind

# Diagnostic levels, as diagnostic_msgs/DiagnosticStatus numbers them.
OK, WARN, ERROR = 0, 1, 2


class ParameterRefused(ValueError):
    """A parameter value the node will not take; str() names the parameter and the reason."""

    def __init__(self, name: str, reason: str):
        super().__init__(f"parameter {name!r} refused: {reason}")
        self.name, self.reason = name, reason


@dataclass(frozen=True)
class ParameterSpec:
    name: str
    kind: str              # "str", "float", "bool", "float_pair", "str_list"
    default: object        # a value, or a function scene -> value for scene-derived defaults
    description: str
    scene_field: bool = False   # True when the value is a Scene field (changing it rebuilds)

    def default_for(self, scene: Scene):
        return self.default(scene) if callable(self.default) else self.default


def _from_scene(name):
    return lambda scene: list(v) if isinstance(v := getattr(scene, name), tuple) else v


def _node_policy(scene: Scene) -> str:
    # An unpowered scene and a command policy that has not yet heard a command apply the
    # same zero torque; serving "zero" as "command" lets the node listen out of the box.
    return "command" if scene.policy == "zero" else scene.policy


def _scene_spec(name, kind, description, default=None):
    return ParameterSpec(name, kind, default or _from_scene(name), description, scene_field=True)


# Every parameter of the node, in one place. Scene-derived defaults come from `scene`.
PARAMETERS = (
    ParameterSpec("scene", "str", "release", "preset scene (config/scenes); chosen at start"),
    _scene_spec("policy", "str", "torque policy: command, command_gravity_compensation, zero, "
                "constant, gravity_compensation, frozen_gravity", _node_policy),
    _scene_spec("constant_torque", "float_pair", "[tau1, tau2] N m for policy constant"),
    _scene_spec("gravity", "float", "gravity magnitude along -y, m/s^2 (0 = off)"),
    _scene_spec("damping", "float", "joint damping d, N m s/rad (0 = off)"),
    _scene_spec("initial_positions", "float_pair", "[q1, q2] rad at start and reset"),
    _scene_spec("initial_velocities", "float_pair", "[qd1, qd2] rad/s at start and reset"),
    _scene_spec("link_lengths", "float_pair", "[l1, l2] m"),
    _scene_spec("link_masses", "float_pair", "[m1, m2] kg"),
    _scene_spec("com_distances", "float_pair", "[r1, r2] m, joint to centre of mass"),
    _scene_spec("com_inertias", "float_pair", "[I1, I2] kg m^2 about each centre of mass"),
    _scene_spec("integrator", "str", "Runge-Kutta method (rk4 default)"),
    _scene_spec("rtol", "float", "relative error tolerance of integrator dopri5"),
    _scene_spec("atol", "float", "absolute error tolerance of integrator dopri5"),
    _scene_spec("step_size", "float", "integration step h, s; must divide 1/publish_rate"),
    ParameterSpec("publish_rate", "float", 100.0, "ticks per simulated second; each tick "
                  "publishes joint_states"),
    ParameterSpec("real_time_factor", "float", 1.0, "simulated seconds per wall second "
                  "(0 = as fast as possible)"),
    ParameterSpec("command_timeout", "float", 0.5, "s of simulated time without a command "
                  "before torque drops to zero (0 = hold forever)"),
    ParameterSpec("torque_limit", "float", 50.0, "commands with |tau| above this (N m) are refused"),
    ParameterSpec("joint_names", "str_list", ["shoulder_joint", "elbow_joint"],
                  "names published in joint_states (match the URDF)"),
    ParameterSpec("frame_id", "str", "", "header.frame_id of joint_states"),
    ParameterSpec("rerun_path", "str", "", "write a Rerun recording here (\"\" = off)"),
    ParameterSpec("rerun_spawn", "bool", False, "spawn a Rerun viewer"),
    ParameterSpec("rerun_connect", "str", "", "stream to a Rerun viewer at this address (\"\" = off)"),
)
SPECS = {spec.name: spec for spec in PARAMETERS}
SCENE_PARAMETERS = tuple(s.name for s in PARAMETERS if s.scene_field)
SCENE_KINDS = {"float": "float", "str": "str", "float_pair": "pair"}   # node kind -> scene kind


def coerce(spec: ParameterSpec, value):
    """The value in the parameter's kind, or ParameterRefused. Numbers, text and pairs are
    checked as scene values are; integers pass as doubles (`-p publish_rate:=100`)."""
    kind, name = spec.kind, spec.name
    if kind in SCENE_KINDS:
        try:
            value = coerce_value(name, SCENE_KINDS[kind], value)
        except SceneError as error:
            raise ParameterRefused(name, str(error)) from None
        return list(value) if kind == "float_pair" else value
    if kind == "bool":
        if not isinstance(value, bool):
            raise ParameterRefused(name, f"must be true or false, got {value!r}")
        return value
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
        raise ParameterRefused(name, f"must be a list, got {value!r}")
    if not all(isinstance(v, str) for v in value):
        raise ParameterRefused(name, f"must be a list of text, got {list(value)!r}")
    return list(value)


@dataclass(frozen=True)
class NodeConfig:
    """A validated, complete set of parameter values and what follows from them."""

    values: dict
    scene: Scene
    steps_per_tick: int

    @property
    def tick_period(self) -> float:
        """Simulated seconds per tick."""
        return 1.0 / self.values["publish_rate"]

    @property
    def wall_period(self) -> float:
        """Wall seconds between ticks; 0 when running as fast as possible."""
        rtf = self.values["real_time_factor"]
        return self.tick_period / rtf if rtf > 0 else 0.0

    @property
    def telemetry_enabled(self) -> bool:
        v = self.values
        return bool(v["rerun_path"] or v["rerun_spawn"] or v["rerun_connect"])

    def with_changes(self, changes: dict) -> "NodeConfig":
        """A new config with `changes` applied, or ParameterRefused with nothing changed."""
        if "scene" in changes and changes["scene"] != self.values["scene"]:
            raise ParameterRefused("scene", "the scene is chosen at start; restart the node "
                                   "with -p scene:=NAME")
        return _build(self.values | changes, load=lambda name: self.scene, changed=list(changes))


def resolve_parameters(overrides: dict) -> NodeConfig:
    """Defaults from the scene named by `scene`, then `overrides`; every value validated."""
    unknown = sorted(set(overrides) - set(SPECS))
    if unknown:
        raise ParameterRefused(unknown[0], f"unknown parameter; known: {', '.join(SPECS)}")
    name = coerce(SPECS["scene"], overrides.get("scene", SPECS["scene"].default))
    scene = _load(name)
    values = {spec.name: spec.default_for(scene) for spec in PARAMETERS} | dict(overrides)
    return _build(values, load=lambda _: scene, changed=list(overrides))


def scene_defaults(scene_name: str) -> dict:
    """Every parameter's default for a scene (what a transport declares)."""
    scene = _load(scene_name)
    return {spec.name: spec.default_for(scene) for spec in PARAMETERS} | {"scene": scene_name}


def _load(name: str) -> Scene:
    try:
        return load_scene(name)
    except SceneError as error:
        raise ParameterRefused("scene", str(error)) from None


def _build(values: dict, load, changed) -> NodeConfig:
    values = {name: coerce(SPECS[name], values[name]) for name in SPECS}
    base = load(values["scene"])
    scene_values = {name: values[name] for name in SCENE_PARAMETERS if name in FIELD_KINDS}
    try:
        scene = base.replace(**scene_values)
    except (SceneError, ParameterError) as error:
        raise ParameterRefused(_blamed(str(error), changed), str(error)) from None
    _check_node_values(values)
    return NodeConfig(values, scene, _steps_per_tick(values["publish_rate"], scene.step_size))


def _blamed(message: str, changed) -> str:
    """The parameter a scene error is about: the one it names, else the first one changed."""
    for name in SCENE_PARAMETERS:
        if name in message:
            return name
    return next((n for n in changed if n in SCENE_PARAMETERS), "scene")


def _check_node_values(values: dict) -> None:
    checks = (
        ("publish_rate", values["publish_rate"] > 0, "must be positive (ticks per second)"),
        ("real_time_factor", values["real_time_factor"] >= 0,
         "must be >= 0 (0 = as fast as possible)"),
        ("command_timeout", values["command_timeout"] >= 0, "must be >= 0 (0 = hold forever)"),
        ("torque_limit", values["torque_limit"] > 0, "must be positive (N m)"),
        ("joint_names", len(values["joint_names"]) == 2, "needs exactly two names"),
    )
    for name, ok, reason in checks:
        if not ok:
            raise ParameterRefused(name, f"{values[name]!r} {reason}")
    joint_names = values["joint_names"]
    if not all(joint_names) or joint_names[0] == joint_names[1]:
        raise ParameterRefused("joint_names", f"{joint_names} must be two distinct, non-empty names")


def _steps_per_tick(rate: float, step_size: float) -> int:
    exact = 1.0 / (rate * step_size)
    steps = round(exact)
    if steps < 1 or abs(steps - exact) > 1e-9 * exact:
        raise ParameterRefused(
            "publish_rate", f"{rate:g} Hz does not divide into steps of {step_size:g} s: one tick "
            f"would be {exact:.6g} steps; choose publish_rate = 1 / (n x step_size)")
    if steps > MAX_STEPS_PER_TICK:
        raise ParameterRefused("publish_rate", f"{rate:g} Hz with step_size {step_size:g} s "
                               f"is {steps} steps per tick; at most {MAX_STEPS_PER_TICK}")
    return steps


# --- messages, transport-neutral ---------------------------------------------------------------

@dataclass(frozen=True)
class JointStateData:
    stamp_ns: int
    frame_id: str
    name: list
    position: list
    velocity: list
    effort: list


@dataclass(frozen=True)
class DiagnosticData:
    stamp_ns: int
    level: int
    name: str
    message: str
    hardware_id: str
    values: list           # [(key, value text)]


COUNTERS = ("received_commands", "refused_commands", "late_ticks", "command_timeouts")


def diagnostic_values(sim, real_time_factor: str, max_abs_residual: float, held: bool,
                      command, steps_per_tick: int, counters=None) -> list:
    """The (key, text) pairs of the simulation's DiagnosticStatus: the node's, and those an
    offline `arm-sim run --bag` writes (its counters stay 0)."""
    counters = counters or {}
    return [
        ("scene", sim.scene.name), ("policy", sim.scene.policy),
        ("sim_time", f"{sim.time:.6f}"), ("real_time_factor", real_time_factor),
        ("energy_residual", "held" if held else f"{sim.residual():.3e}"),
        ("max_abs_energy_residual", f"{max_abs_residual:.3e}"),
        *((name, str(counters.get(name, 0))) for name in COUNTERS),
        ("command", f"{command[0]:g} {command[1]:g}"),
        ("steps_per_tick", str(steps_per_tick)),
        # What the stability guard did: sub-steps per step (1 = plain steps) and refusals.
        ("substeps_per_step", str(sim.substeps)),
        ("substeps_taken", str(sim.substeps_taken)),
        ("refused_steps", str(sim.refused_steps)),
    ]


def split_stamp(stamp_ns: int) -> tuple[int, int]:
    """builtin_interfaces/Time (sec, nanosec) of a stamp in nanoseconds."""
    return divmod(stamp_ns, 1_000_000_000)


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
            from .telemetry import make_recorder  # heavy (rerun); only when asked for
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
