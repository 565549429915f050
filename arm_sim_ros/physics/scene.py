"""Scenes: initial state, physical parameters, the effects they call for, and a torque policy.

A scene is data: presets live in config/scenes/*.yaml. Every value passes through
`Scene.replace`, which validates it, so a scene that exists is one that can be simulated.
"""
from __future__ import annotations

import os
import sys
from dataclasses import dataclass, fields, replace as dataclass_replace
from functools import cached_property
from math import inf, isfinite
from pathlib import Path

from .. import yaml_files
from ..usage import did_you_mean
from .trust.accuracy import DEFAULT_MAX_SUBSTEPS, DEFAULT_TOLERANCE, MAX_SUBSTEPS
from .trust.unestimated import ESTIMATES
from .effects import POLICIES, SERVO_POLICIES, JointLimits, Motors, scene_effects
from .scene_values import MAPPINGS, SceneError, checked
from . import angles, sensing
from .stepping.integrators import DEFAULT_ATOL, DEFAULT_RTOL, INTEGRATORS
from .stepping.stability import UNNAMED, unstiff_method
from .model import MAX_ANGLE, PAIR_FIELDS, ArmParameters, ParameterError


MIN_STEP_SIZE = 1e-9      # s: stamps count whole nanoseconds
MAX_DURATION = 1e9        # s (~32 years): nanosecond stamps stay within 64 bits


@dataclass(frozen=True)
class Scene:
    name: str = "release"
    description: str = ""
    initial_positions: tuple[float, float] = (0.0, 0.0)
    initial_velocities: tuple[float, float] = (0.0, 0.0)
    gravity: float = 9.81            # magnitude along -y; 0 = no gravity effect
    damping: float | tuple = 0.0     # d (D = d I) or [d1, d2] per joint; 0 = no damping effect
    link_lengths: tuple[float, float] = ArmParameters.link_lengths
    link_masses: tuple[float, float] = ArmParameters.link_masses
    com_distances: tuple[float, float] = ArmParameters.com_distances
    com_inertias: tuple[float, float] = ArmParameters.com_inertias
    policy: str = "zero"
    constant_torque: tuple[float, float] = (0.0, 0.0)
    setpoint: tuple[float, float] = (0.0, 0.0)   # policy setpoint: each servo joint's target
    # Effects named by a mapping of their parameters (effects/*.py); None = absent.
    springs: dict | None = None
    payload: dict | None = None
    motors: dict | None = None
    effort_limits: tuple | None = None
    controller_model: dict | None = None
    friction: dict | None = None
    joint_limits: dict | None = None
    servo: dict | None = None
    sensors: dict | None = None      # what is read in place of the state (physics/sensing/)
    command_delay: float = 0.0       # s: a command given at t acts from t + command_delay
    integrator: str = ""             # "": none named, the scene's `method` chooses one
    rtol: float = DEFAULT_RTOL       # error tolerances of the embedded pair (dopri5) only
    atol: float = DEFAULT_ATOL
    tolerance: float = DEFAULT_TOLERANCE   # local error per second a step may make (accuracy.py)
    max_substeps: int = DEFAULT_MAX_SUBSTEPS   # the most sub-steps a tolerance may ask of a step
    # what a run computes of its own error (trust/unestimated.py): global (the shadow and
    # its checks) or off (the steps alone: no error estimate, so tolerance 0)
    estimate: str = "global"
    # on: a step beyond the method's stability limit is split into sub-steps (stability.py);
    # off: every step taken whole, as a stability study needs to find where it diverges
    stability_plan: str = "on"
    step_size: float = 0.01
    duration: float = 0.5

    def __post_init__(self):
        for f in fields(self):
            object.__setattr__(self, f.name, coerce_value(f.name, FIELD_KINDS[f.name],
                                                          getattr(self, f.name)))
        for key, at in (("initial_positions", self.initial_positions), ("setpoint", self.setpoint)):
            if not max(abs(v) for v in at) <= MAX_ANGLE:     # a set-point: as commands' are
                raise SceneError(f"{key} = {list(at)} is beyond {MAX_ANGLE:g} rad in magnitude")
        if self.gravity < 0:
            raise SceneError(f"gravity = {self.gravity} is a magnitude (along -y); it must be >= 0")
        if min(_pair(self.damping)) < 0:
            raise SceneError(f"damping = {_text(self.damping)} would add energy; it must be >= 0")
        if self.policy not in POLICIES:
            raise SceneError(f"policy {self.policy!r} is unknown; choose one of {', '.join(POLICIES)}")
        if self.policy == "setpoint" and self.servo is None:
            raise SceneError("policy setpoint needs a servo (scene key servo: interface, kp ...)")
        if self.servo is not None and self.policy not in SERVO_POLICIES:
            raise SceneError(f"servo needs policy {', '.join(SERVO_POLICIES)}, not "
                             f"{self.policy!r}")
        if self.integrator and self.integrator not in INTEGRATORS:
            raise SceneError(f"integrator {self.integrator!r} is unknown; choose one of "
                             f"{', '.join(INTEGRATORS)}, or name none (\"\": {UNNAMED})")
        for name in ("rtol", "atol"):
            if not getattr(self, name) >= 1e-14:
                raise SceneError(f"{name} = {getattr(self, name)} must be at least 1e-14 "
                                 "(tighter than rounding cannot be met)")
        if not self.tolerance >= 0:
            raise SceneError(f"tolerance = {self.tolerance} must be >= 0 (local error per "
                             "simulated second; 0: estimate only, never split a step)")
        if self.estimate not in ESTIMATES:
            raise SceneError(f"estimate {self.estimate!r} is unknown; choose global (the "
                             "error estimate, the default) or off (none)")
        if self.estimate == "off" and self.tolerance != 0:
            raise SceneError(f"estimate off computes no error estimate, so it cannot hold "
                             f"tolerance = {self.tolerance:g}: set tolerance 0, or leave it "
                             "out (estimate off alone sets it to 0)")
        if self.stability_plan not in ("on", "off"):
            raise SceneError(f"stability_plan {self.stability_plan!r} is unknown; choose on "
                             "(sub-steps where a step would be unstable, the default) or off "
                             "(every step whole: a stability study)")
        if not 1 <= self.max_substeps <= MAX_SUBSTEPS:
            raise SceneError(f"max_substeps = {self.max_substeps} must be a whole number from 1 "
                             f"to {MAX_SUBSTEPS} (sub-steps a tolerance may ask of one step)")
        if not MIN_STEP_SIZE <= self.step_size <= MAX_DURATION:
            raise SceneError(f"step_size = {self.step_size} must be positive: from "
                             f"{MIN_STEP_SIZE:g} s (stamps count nanoseconds) to {MAX_DURATION:g} s")
        if not self.duration >= 0:
            raise SceneError(f"duration = {self.duration} must not be negative")
        try:
            self.arm
        except ParameterError as error:
            raise SceneError(str(error)) from None
        self._check_plan_inputs()
        limits = JointLimits.make(**self.joint_limits) if self.joint_limits else None
        if limits is not None and limits.hard and limits.inside(self.initial_positions):
            raise SceneError(f"initial_positions: {limits.inside(self.initial_positions)} "
                             "(hard joint_limits cannot start beyond)")

    def _check_plan_inputs(self) -> None:
        """Each effect built, and the stiffness and frequency the step plan derives from it
        doubles: values whose products overflow (a torque_constant of 1e200, a believed arm
        of 1e200 m) are refused here, in the physics' words, not later in the planner."""
        arm = self.arm
        try:
            effects = scene_effects(self)
            sensing.check(self)          # whole numbers of steps
        except ParameterError as error:
            raise SceneError(str(error)) from None
        for effect in effects:
            try:
                derived = [effect.stiffness(arm), effect.frequency(arm)]
                for name in ("engaged_stiffness", "engaged_frequency"):   # a compliant
                    if hasattr(effect, name):                             # limit's, engaged
                        derived.append(getattr(effect, name)(arm))
            except (OverflowError, ZeroDivisionError, ValueError):
                derived = (inf,)
            if not all(isfinite(v) for v in derived):
                raise SceneError(f"{effect.name or type(effect).__name__}: its stiffness "
                                 "(1/s) and frequency (rad/s), which set the step plan, are "
                                 "beyond double precision with these values; use values at a "
                                 "robot's scale")

    @cached_property   # the integrator named, else stability.unstiff_method's choice (cached:
    def method(self) -> str:    # a frozen scene's values never change; a sweep asks often)
        return self.integrator or unstiff_method(scene_effects(self), self.arm, self.step_size)

    @cached_property
    def links(self) -> ArmParameters:
        """The bare links: no payload, no rotor inertia."""
        return ArmParameters(**{name: getattr(self, name) for name in PAIR_FIELDS})

    @cached_property
    def arm(self) -> ArmParameters:
        """The arm the physics moves: links, the payload folded into link 2, and the motors'
        reflected rotor inertia."""
        arm = self.links
        if self.motors is not None:
            arm = dataclass_replace(arm, armature=Motors(**self.motors).armature)
        if self.payload is not None:
            arm = arm.with_payload(self.payload["mass"])
        return arm

    def replace(self, **overrides) -> "Scene":
        """A new scene with `overrides`; `effect.key` names one parameter of an effect."""
        merged = {}
        for key, value in overrides.items():
            effect, dot, parameter = key.partition(".")
            if dot and effect in MAPPINGS:
                current = merged.get(effect, getattr(self, effect)) or {}
                merged[effect] = dict(current) | {parameter: value}
            elif key in FIELD_KINDS:
                merged[key] = value
            else:
                raise SceneError(unknown_key(key))
        if "estimate" in merged:       # YAML's `off` (a bool) is the word here already
            merged["estimate"] = coerce_value("estimate", "str", merged["estimate"])
        if merged.get("estimate") == "off" and "tolerance" not in merged:
            merged["tolerance"] = 0.0   # no estimate, no tolerance: unless named beside it
        return dataclass_replace(self, **merged)

    def with_text_overrides(self, assignments, given=None) -> "Scene":
        """Apply `key=value` strings as the command line gives them (pairs as `1,0`), in one
        change with the values `given` beside them (--tolerance, --estimate ...): one rule
        for what goes together (estimate off alone sets tolerance 0, not beside one)."""
        overrides = dict(given or {})
        for text in assignments:
            key, sep, value = text.partition("=")
            key = key.strip()
            if not sep or not key:
                raise SceneError(f"--set {text!r} is not of the form key=value")
            if key in overrides:        # the last would win unseen
                beside = (f"beside --{key.replace('_', '-')}" if key in (given or {})
                          else "twice")
                raise SceneError(f"--set {key} is given {beside}; give it once")
            overrides[key] = parse_value(key, value)
        return self.replace(**overrides)

    def steps_for(self, duration: float, step_size: float | None = None) -> int:
        """The whole number of steps that covers `duration`; anything else is refused."""
        h = self.step_size if step_size is None else step_size
        if not (isfinite(duration) and 0 <= duration <= MAX_DURATION):
            raise SceneError(f"duration = {duration} must be a number of seconds from 0 to "
                             f"{MAX_DURATION:g} (stamps count nanoseconds in 64 bits)")
        steps = round(duration / h)
        if abs(steps * h - duration) > 1e-9 * max(1.0, duration):
            raise SceneError(f"duration {duration} s is not a whole number of steps of {h} s "
                             f"({duration / h:.6g} steps)")
        return steps


FIELD_KINDS = {f.name: ("pair" if "tuple" in str(f.type) else f.type if f.type in ("float", "int")
                        else "str") for f in fields(Scene)}
FIELD_KINDS |= {"damping": "float_or_pair", "effort_limits": "pair_or_none"}
FIELD_KINDS |= {name: "effect" for name in MAPPINGS}


def _pair(value) -> tuple:
    return value if isinstance(value, tuple) else (value, value)


def _text(value) -> str:
    return str(list(value)) if isinstance(value, tuple) else str(value)


def coerce_value(name: str, kind: str, value):
    """`value` as the kind needs it (scene_values.checked), its numbers written in degrees
    (`90deg`) in radians first, or SceneError saying why. Also the node's check for its
    own numbers, text and pairs."""
    value = in_radians(name, value)
    if kind == "effect" and isinstance(value, dict):
        value = {k: in_radians(f"{name}.{k}", v) for k, v in value.items()}
    return checked(name, kind, value)


def unknown_key(key: str) -> str:
    """Why `key` is no scene key, with the closest one (an effect's keys as effect.key)."""
    keys = [f"{effect}.{p.name}" for effect, cls in MAPPINGS.items() for p in cls.parameters]
    hint = did_you_mean(key, FIELD_KINDS) or did_you_mean(key, keys) or next(
        (f"did you mean {k!r}? " for k in keys if k.endswith(f".{key}")), "")
    return f"unknown scene key {key!r}; {hint}known keys: {', '.join(FIELD_KINDS)}"


def parse_value(key: str, text: str):
    """A value as the command line writes it: numbers, pairs as `1,0`, text."""
    effect, dot, name = key.partition(".")
    if dot and effect in MAPPINGS:
        known = {p.name: p for p in MAPPINGS[effect].parameters}
        if name not in known:
            hint = did_you_mean(key, [f"{effect}.{k}" for k in known])
            raise SceneError(f"{key} is not a key of {effect}; {hint}its keys: {', '.join(known)}")
        kind = known[name].kind
    elif key in FIELD_KINDS:
        kind = FIELD_KINDS[key]
    else:
        raise SceneError(unknown_key(key))
    if kind in ("float_or_pair", "pair_or_none"):
        kind = "pair" if "," in text else "float"
    if kind == "effect":
        raise SceneError(f"--set {key}=... sets one parameter at a time: {key}.NAME=VALUE")
    if kind == "names":
        return tuple(v.strip() for v in text.split(","))
    try:
        if kind == "pair":
            return tuple(_number(key, v) for v in text.split(","))
        if kind == "float":
            return _number(key, text)
        if kind == "int":
            return _whole(key, text)
    except SceneError:
        raise
    except ValueError:
        expected = {"pair": "two numbers like 1,0", "int": "a whole number"}.get(kind, "a number")
        raise SceneError(f"{key}={text!r} is malformed: expected {expected}") from None
    return text


def _whole(key: str, text: str):
    """An integer as written (`9223372036854775807`), never through a double, which holds
    whole numbers exactly only up to 2^53; `7.0` or `1e3` are read as doubles."""
    text = text.strip()
    if len(text.lstrip("+-")) > 400:           # int() refuses 4300 digits with a traceback
        raise SceneError(f"{key}: an integer of {len(text)} digits is beyond its range")
    try:
        return int(text)
    except ValueError:
        return float(text)


def _number(key: str, text: str) -> float:
    """A number; an angle may be given in degrees as `90deg` (angles.py)."""
    text = text.strip()
    return angles.degrees(key, text, SceneError) if text.endswith("deg") else float(text)


def in_radians(key: str, value):
    """`value` with its numbers in degrees in radians (angles.py's rule), or SceneError."""
    return angles.in_radians(key, value, parse_value, SceneError)


def scene_dirs() -> list[Path]:
    """Where presets live: the source tree, then where pip or colcon install data_files."""
    source_tree = Path(__file__).resolve().parents[2]
    candidates = [Path(os.environ["ARM_SIM_SCENES"])] if os.environ.get("ARM_SIM_SCENES") else []
    candidates += [source_tree / "config" / "scenes",
                   Path(sys.prefix) / "share" / "arm_sim_ros" / "config" / "scenes"]
    try:  # a colcon install puts them in the package's share directory
        from ament_index_python.packages import get_package_share_directory
        candidates.append(Path(get_package_share_directory("arm_sim_ros")) / "config" / "scenes")
    except Exception:
        pass
    return [p for p in candidates if p.is_dir()]


def preset_names() -> list[str]:
    return sorted({p.stem for d in scene_dirs()[:1] for p in d.glob("*.yaml")})


def load_scene(name: str = "release") -> Scene:
    """A preset by name, or a scene file by path (anything ending in .yaml/.yml or with a
    directory in it); the preset directories are searched in scene_dirs() order."""
    if name.endswith((".yaml", ".yml")) or os.sep in name:
        path = Path(name)
        if not _is_file(path, Path.exists):     # a directory: yaml_files says so
            raise SceneError(f"scene file {name} does not exist")
        return scene_from_file(path, path.stem)
    for directory in scene_dirs():
        path = directory / f"{name}.yaml"
        if _is_file(path):
            return scene_from_file(path, name)
    names = preset_names()
    raise SceneError(f"unknown scene {name!r}; {did_you_mean(name, names)}presets: "
                     f"{', '.join(names) or 'none found'} (or give a path to a .yaml file)")


def _is_file(path: Path, test=Path.is_file) -> bool:
    try:
        return test(path)
    except (OSError, ValueError):          # a name too long, a NUL byte in it
        return False


def scene_from_file(path: Path, name: str) -> Scene:
    try:
        data = yaml_files.load(path, "scene file")
    except yaml_files.YamlFileError as error:
        raise SceneError(str(error)) from None
    if not isinstance(data := {} if data is None else data, dict):
        raise SceneError(f"scene file {path} must hold a mapping of keys to values")
    if data and not set(data) & set(FIELD_KINDS):     # /etc/shadow: its lines never echoed
        raise SceneError(f"{path} is not a scene file: not one of its keys is a scene key "
                         "(`arm-sim scenes` lists the presets)")
    try:
        return Scene(name=name).replace(**data)
    except SceneError as error:
        raise SceneError(f"scene {name!r} ({path}): {error}") from None
