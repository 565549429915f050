"""The node's parameters, declared in one place: name, kind, default, unit and meaning.

`resolve_parameters` turns overrides into a validated `NodeConfig`; a value the simulation
cannot take is refused with a reason (`ParameterRefused`) and nothing changes.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

from ...interface import JOINT_COMMANDS_TOPIC, JOINT_NAMES, JOINT_STATES_TOPIC
from ...physics.effects import EffortLimits
from ...physics.effects.base import REQUIRED
from ...physics.urdf import read as urdf
from ...physics.model import ParameterError, brief
from ...physics.scene import (FIELD_KINDS, MAPPINGS, UNNAMED, Scene, SceneError,
                              load_scene)
from .recording_targets import rerun_path_problem, viewer_address_problem
from ...usage import did_you_mean, one_line
from .values import ParameterRefused, coerce

MAX_STEPS_PER_TICK = 100_000      # beyond this one tick would freeze the node for seconds
CLOCK_ORIGINS = ("zero", "wall")  # /clock and stamps from 0, or from the wall clock at start
MAX_WALL_PERIOD = 3600.0          # wall s between ticks: slower is no longer a running node


RECORDING = {"rerun_path": rerun_path_problem, "rerun_connect": viewer_address_problem}


# When a parameter may change (main.py's --help prints it): the one place it is decided.
START = "start only"                   # refused while running (START_ONLY)
KEPT = "live, state kept"              # the physics changes from the next step (LIVE)
RESTART = "live, restarts the scene"   # a Scene field: the scene restarts with it
ANYTIME = "live"


@dataclass(frozen=True)
class ParameterSpec:
    name: str
    kind: str              # "str", "float", "int", "bool", "float_pair", "str_list"
    default: object        # a value, or a function scene -> value for scene-derived defaults
    meaning: str
    scene_field: bool = False   # True when the value is a Scene field (changing it rebuilds)
    effect: object = None       # an effect's key: the physics Parameter that checks it
    when: str = ANYTIME         # START, KEPT, RESTART or ANYTIME

    def default_for(self, scene: Scene):
        return self.default(scene) if callable(self.default) else self.default

    @property
    def description(self) -> str:
        """The meaning, and when it may change if not while running."""
        if self.effect is not None:
            return f"{self.meaning} ({'chosen at start' if self.when == START else 'changes live'})"
        return self.meaning + ("; chosen at start" if self.when == START else "")


def _from_scene(name):
    return lambda scene: list(v) if isinstance(v := getattr(scene, name), tuple) else v


def _node_policy(scene: Scene) -> str:
    # An unpowered scene and a command policy that has not yet heard a command apply the
    # same zero torque; serving "zero" as "command" lets the node listen out of the box.
    return "command" if scene.policy == "zero" else scene.policy


def _scene_spec(name, kind, description, default=None, when=RESTART):
    return ParameterSpec(name, kind, default or _from_scene(name), description, scene_field=True,
                         when=when)


# Effects whose keys are start-only, and why. The others' keys (effort_limits, friction,
# controller_model, payload) change while the node runs: the physics is rebuilt from the next
# step with the state and energy books carried over (none of them stores energy; a payload
# books what changes hands in payload_exchange).
START_ONLY_WHY = {
    "motors": "the rotor inertia is in the mass matrix and the winding currents in the state",
    "springs": "a spring's stored energy would change with nothing to book it",
    "joint_limits": "the arm may stand beyond a new limit",
}


def _effect_value(effect: str, key: str | None):
    """scene -> its value of `effect.key` (the pair of effort_limits when key is None), None
    where the scene does not name it."""
    def value(scene):
        named = getattr(scene, effect)
        named = named if key is None or named is None else named.get(key)
        return list(named) if isinstance(named, tuple) else named
    return value


def _effect_spec(effect: str, key: str | None, parameter) -> ParameterSpec:
    default = parameter.default
    unset = (f"; not set: no {effect}" if default is REQUIRED else "" if default is None
             else f"; not set: {list(default) if isinstance(default, tuple) else default}")
    return ParameterSpec(
        effect if key is None else f"{effect}.{key}",
        {"pair": "float_pair", "names": "str_list", "choice": "str", "int": "int"}.get(
            parameter.kind, "float"),
        _effect_value(effect, key),
        f"{parameter.description}, {parameter.unit}{unset}", scene_field=True, effect=parameter,
        when=START if effect in START_ONLY_WHY else KEPT)


# One parameter per scene key of every effect and of the sensors, named and checked as the
# scene file names and checks it (`friction.coulomb`, `sensors.delay`); generated from their
# own key lists.
EFFECT_PARAMETERS = (_effect_spec("effort_limits", None, EffortLimits.parameter),) + tuple(
    _effect_spec(effect, p.name, p) for effect, kind in MAPPINGS.items()
    for p in kind.parameters)


# Every parameter of the node, in one place. Scene-derived defaults come from `scene`.
PARAMETERS = (
    ParameterSpec("scene", "str", "release", "preset scene (config/scenes)", when=START),
    ParameterSpec("robot_description", "str", "", "URDF of a planar 2R arm: its link lengths, "
                  "masses, inertias, limits, damping, friction and joint names replace the "
                  "scene's (\"\" = the scene's arm)", when=START),
    _scene_spec("policy", "str", "torque policy: command, command_gravity_compensation, zero, "
                "constant, gravity_compensation, frozen_gravity, setpoint (servos)", _node_policy),
    _scene_spec("constant_torque", "float_pair", "[tau1, tau2] N m for policy constant"),
    _scene_spec("gravity", "float", "gravity magnitude along -y, m/s^2 (0 = off)"),
    _scene_spec("damping", "float_or_pair", "joint damping d or [d1, d2], N m s/rad (0 = off)",
                when=KEPT),
    *EFFECT_PARAMETERS,
    _scene_spec("command_delay", "float", "s from a command (torque, set-point, the policy's or "
                "servo's torque) to when it acts; a whole number of steps (0 = none)", when=KEPT),
    _scene_spec("initial_positions", "float_pair", "[q1, q2] rad at start and reset"),
    _scene_spec("initial_velocities", "float_pair", "[qd1, qd2] rad/s at start and reset"),
    _scene_spec("link_lengths", "float_pair", "[l1, l2] m"),
    _scene_spec("link_masses", "float_pair", "[m1, m2] kg"),
    _scene_spec("com_distances", "float_pair", "[r1, r2] m, joint to centre of mass"),
    _scene_spec("com_inertias", "float_pair", "[I1, I2] kg m^2 about each centre of mass"),
    _scene_spec("integrator", "str", "Runge-Kutta method (\"\": none named, the default: "
                f"{UNNAMED})"),
    _scene_spec("rtol", "float", "relative error tolerance of integrator dopri5"),
    _scene_spec("atol", "float", "absolute error tolerance of integrator dopri5"),
    _scene_spec("tolerance", "float", "local error per simulated second a fixed step may "
                "make before it splits into sub-steps (0 = estimate only)"),
    _scene_spec("max_substeps", "int", "the most sub-steps the tolerance may ask of one step; "
                "past it the step is taken at the cap and the node says so once; the node "
                "refuses physics whose stability plan needs more"),
    _scene_spec("estimate", "str", "what the run computes of its own error: global (the "
                "error estimate, in diagnostics and the recording) or off (none: the steps "
                "alone, cheaper; it sets tolerance to 0)"),
    _scene_spec("step_size", "float", "integration step h, s; must divide 1/publish_rate"),
    ParameterSpec("publish_rate", "float", 100.0, "ticks per simulated second; each tick "
                  "publishes joint_states"),
    ParameterSpec("real_time_factor", "float", 1.0, "simulated seconds per wall second "
                  "(0 = as fast as possible)"),
    ParameterSpec("command_timeout", "float", 0.5, "s of simulated time without a command "
                  "before torque drops to zero (0 = hold forever)"),
    ParameterSpec("torque_limit", "float", 50.0, "commands with |tau| above this (N m) are refused"),
    ParameterSpec("joint_names", "str_list", list(JOINT_NAMES),
                  "names published in joint_states (match the URDF)"),
    ParameterSpec("frame_id", "str", "", "header.frame_id of joint_states"),
    ParameterSpec("rerun_path", "str", "", "write a Rerun recording here (\"\" = off)"),
    ParameterSpec("rerun_spawn", "bool", False, "spawn a Rerun viewer"),
    ParameterSpec("rerun_connect", "str", "", "stream to a Rerun viewer at this address (\"\" = off)"),
    ParameterSpec("joint_states_topic", "str", JOINT_STATES_TOPIC, "topic of the published "
                  "sensor_msgs/JointState", when=START),
    ParameterSpec("joint_commands_topic", "str", JOINT_COMMANDS_TOPIC, "topic of "
                  "sensor_msgs/JointState effort commands (ros2_control's topic-based "
                  "hardware interface)", when=START),
    ParameterSpec("publish_clock", "bool", True, "publish rosgraph_msgs/Clock on /clock every "
                  "tick: simulated time, equal to the JointState stamps"),
    ParameterSpec("clock_origin", "str", "zero", "what /clock and the stamps count from: zero "
                  "(simulated time from 0 at start, as Gazebo does) or wall (the wall clock at "
                  "start + simulated time)", when=START),
    ParameterSpec("lockstep", "bool", False, "advance exactly one tick per command that "
                  "answers the latest state (a JointState command carrying its stamp; an "
                  "unstamped command answers the latest on arrival), for deterministic "
                  "controller tests"),
    ParameterSpec("paused", "bool", False, "start paused: no physics until the Simulation "
                  "Interfaces' set_simulation_state plays or step_simulation steps (a test "
                  "starts the loop when its controller is up)", when=START),
    ParameterSpec("lockstep_wait", "float", 0.1, "in lockstep, while a node listens on "
                  "/clock, a tick of its own once no command came for this long (wall s; 0 = "
                  "never): controller_manager under use_sim_time waits for the clock to move "
                  "before it commands"),
)
SPECS = {spec.name: spec for spec in PARAMETERS}
SCENE_PARAMETERS = tuple(s.name for s in PARAMETERS if s.scene_field)
# Physics that changes while it runs without a restart: the state and the books carry over.
LIVE = tuple(s.name for s in PARAMETERS if s.when == KEPT)
# Fixed once running; refused in this order (the node's own before the effects' keys).
START_ONLY = tuple(s.name for s in sorted(PARAMETERS, key=lambda s: s.effect is not None)
                   if s.when == START)
READ_ONLY = ("scene", "robot_description")   # declared read-only (both transports)
EFFECT_GROUPS = {effect: tuple((s.name, s.name.partition(".")[2]) for s in EFFECT_PARAMETERS
                               if s.name.startswith(effect + "."))
                 for effect in MAPPINGS}     # mapping effect -> (parameter, key) pairs


def when_changed(name: str) -> str:
    """What setting `name` while the node runs does."""
    return SPECS[name].when


@dataclass(frozen=True)
class NodeConfig:
    """A validated, complete set of parameter values and what follows from them."""

    values: dict
    scene: Scene
    steps_per_tick: int
    # the parameters given a value other than the scene's default at start: the ones a
    # physics that cannot be built is blamed on (rclpy hands every parameter over, set or not)
    given: tuple = field(default=(), compare=False)

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
        _check_known(changes)
        for name in START_ONLY:
            # compared as taken: [100, 50] or a rclpy array is the pair [100.0, 50.0]
            if name in changes and coerce(SPECS[name], changes[name]) != self.values[name]:
                why = START_ONLY_WHY.get(name.partition(".")[0], "it is chosen at start")
                raise ParameterRefused(name, f"{name} is start-only ({why}); restart the node "
                                       f"with -p {name}:=VALUE")
        config = _build(self.values | changes, load=lambda name: self.scene,
                        changed=list(changes))
        check_recording(config.values, [n for n in RECORDING if config.values[n] != self.values[n]])
        return config


def resolve_parameters(overrides: dict) -> NodeConfig:
    """Defaults from the scene named by `scene` (read through `robot_description` when one is
    given), then `overrides`; every value validated."""
    _check_known(overrides)
    values, scene = _defaults(*(coerce(SPECS[name], overrides.get(name, SPECS[name].default))
                                for name in READ_ONLY))
    config = _build(values | dict(overrides), load=lambda _: scene, changed=list(overrides))
    check_recording(config.values)
    return replace(config, given=tuple(n for n in overrides
                                       if config.values[n] != coerce(SPECS[n], values[n])))


def check_recording(values: dict, names=RECORDING) -> None:
    """The recording targets `names` of `values`, checked before the node opens them."""
    for name in names:
        if (problem := RECORDING[name](values[name])) is not None:
            raise ParameterRefused(name, problem)


def _check_known(names) -> None:
    unknown = sorted(set(names) - set(SPECS))
    if unknown:
        raise ParameterRefused(unknown[0], f"unknown parameter; {did_you_mean(unknown[0], SPECS)}"
                                           f"known: {', '.join(SPECS)}")


def scene_defaults(scene_name: str, robot_description: str = "") -> dict:
    """Every parameter's default for a scene and URDF (what a transport declares)."""
    return _defaults(scene_name, robot_description)[0]


def _defaults(scene_name: str, robot_description: str) -> tuple[dict, Scene]:
    """(every parameter's default, the scene read through the URDF), the URDF read once."""
    scene, names = _load(scene_name), {}
    if robot_description:
        try:
            robot = urdf.read_urdf(robot_description)
            scene = robot.scene(scene)
        except SceneError as error:
            raise ParameterRefused("robot_description", str(error)) from None
        names = {"joint_names": list(robot.joint_names)}
    return ({spec.name: spec.default_for(scene) for spec in PARAMETERS} | names
            | {"scene": scene_name, "robot_description": robot_description}), scene


def _load(name: str) -> Scene:
    try:
        return load_scene(name)
    except SceneError as error:
        raise ParameterRefused("scene", str(error)) from None


def _build(values: dict, load, changed) -> NodeConfig:
    values = {name: coerce(SPECS[name], values[name]) for name in SPECS}
    if values["estimate"] == "off" and "estimate" in changed and "tolerance" not in changed:
        values["tolerance"] = 0.0        # as in a scene: estimate off alone, no tolerance
    base = load(values["scene"])
    scene_values = {name: values[name] for name in SCENE_PARAMETERS if name in FIELD_KINDS}
    for effect, keys in EFFECT_GROUPS.items():   # a key not set leaves it to the effect
        scene_values[effect] = {key: values[name] for name, key in keys
                                if values[name] is not None} or None
    try:
        scene = base.replace(**scene_values)
    except (SceneError, ParameterError) as error:
        raise ParameterRefused(blamed(str(error), changed), str(error)) from None
    _check_node_values(values)
    return NodeConfig(values, scene, steps_per_tick(values["publish_rate"], scene.step_size))


def blamed(message: str, changed) -> str:
    """The parameter a scene error is about: of those it names, one just changed (the longest
    name: `joint_limits.damping` rather than `damping`); else a key just changed of an effect
    it names (`friction.static` when friction.coulomb is missing); else the first named or
    changed."""
    named = [name for name in SCENE_PARAMETERS if name in message]
    effects = {name.partition(".")[0] for name in named}
    for pool in ([n for n in named if n in changed],
                 [n for n in changed if n in SCENE_PARAMETERS and n.partition(".")[0] in effects],
                 named):
        if pool:
            return max(pool, key=len)
    return next((n for n in changed if n in SCENE_PARAMETERS), "scene")


def _check_node_values(values: dict) -> None:
    checks = (
        ("publish_rate", values["publish_rate"] > 0, "must be positive (ticks per second)"),
        ("real_time_factor", values["real_time_factor"] >= 0,
         "must be >= 0 (0 = as fast as possible)"),
        ("command_timeout", values["command_timeout"] >= 0, "must be >= 0 (0 = hold forever)"),
        ("lockstep_wait", 0 <= values["lockstep_wait"] <= MAX_WALL_PERIOD,
         f"must be within [0, {MAX_WALL_PERIOD:g}] (wall s; 0 = wait for commands forever)"),
        ("torque_limit", values["torque_limit"] > 0, "must be positive (N m)"),
        ("joint_names", len(values["joint_names"]) == 2, "needs exactly two names"),
        ("clock_origin", values["clock_origin"] in CLOCK_ORIGINS,
         f"must be one of {', '.join(CLOCK_ORIGINS)}"),
    )
    for name, ok, reason in checks:
        if not ok:
            raise ParameterRefused(name, f"{brief(values[name])} {reason}")
    rtf, tick = values["real_time_factor"], 1.0 / values["publish_rate"]
    if rtf and not tick / rtf <= MAX_WALL_PERIOD:      # 5e-324: the period is inf
        raise ParameterRefused("real_time_factor", (
            f"{rtf:g} would stretch one tick ({tick:g} s simulated) over {tick / rtf:.3g} s of "
            f"wall time; at most {MAX_WALL_PERIOD:g} s: choose at least "
            f"{tick / MAX_WALL_PERIOD:.3g}, or 0 (as fast as possible)"))
    joint_names = values["joint_names"]
    if not all(joint_names) or joint_names[0] == joint_names[1]:
        raise ParameterRefused("joint_names", f"{brief(joint_names)} must be two distinct, "
                               "non-empty names")


def steps_per_tick(rate: float, step_size: float) -> int:
    exact = 1.0 / rate / step_size     # rate * step_size can underflow to 0 (a rate of 5e-324)
    if exact == float("inf"):
        raise ParameterRefused("publish_rate", f"{rate:g} Hz with step_size {step_size:g} s "
                               f"is more steps per tick than a double holds; at most "
                               f"{MAX_STEPS_PER_TICK}")
    steps = round(exact)
    if steps < 1 or abs(steps - exact) > 1e-9 * exact:
        raise ParameterRefused(
            "publish_rate", f"{rate:g} Hz does not divide into steps of {step_size:g} s: one tick "
            f"would be {exact:.6g} steps; choose publish_rate = 1 / (n x step_size)")
    if steps > MAX_STEPS_PER_TICK:
        raise ParameterRefused("publish_rate", f"{rate:g} Hz with step_size {step_size:g} s "
                               f"is {steps} steps per tick; at most {MAX_STEPS_PER_TICK}")
    return steps
