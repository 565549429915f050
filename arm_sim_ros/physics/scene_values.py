"""A scene's values checked as their kinds need them: numbers, whole numbers, text, pairs and
each effect's (and the sensors') mapping, the one rule for a scene file, `--set` and the
node's parameters (scene.py holds the scene itself)."""
from __future__ import annotations

from math import isfinite

from .effects import BUILDERS, MAPPING_EFFECTS, EffortLimits, validate
from .effects.base import whole_number
from . import sensing
from .model import ParameterError, brief

# YAML 1.1 (PyYAML, and rcl for `-p`) reads an unquoted off (no, false ...) as a bool: a
# text key one of whose words is `off` takes that bool back as the word, so that
# `estimate: off` in a scene file means what `-p estimate:=off` means on the node.
FALSE_AS_TEXT = {"estimate": "off"}
# Scene keys whose value is a mapping of parameters (each effect's, the sensors'), and how
# a validated mapping is built for its cross-checks.
MAPPINGS = MAPPING_EFFECTS | {"sensors": sensing.Sensors}
BUILT = BUILDERS | {"sensors": sensing.Sensors}


class SceneError(ValueError):
    """A scene or override that cannot be simulated; the message says what and why."""


def _as_text(value) -> str:
    """Why a number arrived as text: ROS 2 (rcl, C's strtod) reads one a double cannot hold
    (beyond 1.8e308, or below the smallest normal double and not exact) as text."""
    try:
        number = float(value) if isinstance(value, str) and len(value) < 5000 else None
    except ValueError:
        return ""
    if number is None or number != number:
        return ""
    return (" (text: ROS 2 reads a number beyond the doubles, or below 2.2e-308 and not "
            "exactly a double, as text; write 0.0 or a number in range)")


def checked(name: str, kind: str, value):
    """`value` as the kind ("float", "int", "str", "pair", or a scene's "float_or_pair",
    "pair_or_none", "effect") needs it, or SceneError saying why (its numbers in radians
    already: scene.coerce_value)."""
    if kind == "float_or_pair":
        if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
            return checked(name, "float", value)
        pair = checked(name, "pair", value)
        return 0.0 if pair == (0.0, 0.0) else pair
    if kind == "pair_or_none":
        return None if value is None else effect_value(name, EffortLimits.parameter, value)
    if kind == "effect":
        if value is None:
            return None
        try:
            values = validate(name, MAPPINGS[name].parameters, value)
            if name in BUILT:
                BUILT[name](**values)     # its cross-checks: windings all three or none ...
        except ParameterError as error:
            raise SceneError(str(error)) from None
        return values
    if kind == "int":
        try:
            return whole_number(name, value, "1")
        except ParameterError as error:
            raise SceneError(str(error)) from None
    if kind == "str":
        if value is False and name in FALSE_AS_TEXT:
            value = FALSE_AS_TEXT[name]
        if not isinstance(value, str):
            bare = " (a bare yes, on or true is read as a bool)" if value is True else ""
            raise SceneError(f"{name} must be text, got {brief(value)}{bare}")
        return value
    if kind == "pair":
        if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
            raise SceneError(f"{name} must be a list of two numbers, got {brief(value)}")
        if len(value) != 2:
            raise SceneError(f"{name} needs two numbers (one per joint or link), got {list(value)}")
        return tuple(checked(f"{name}[{i}]", "float", v) for i, v in enumerate(value))
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{name} must be a number, got {brief(value, 60)}{_as_text(value)}")
    try:
        value = float(value)
    except OverflowError:
        raise SceneError(f"{name} = {brief(value, 20)} is beyond the largest double") from None
    if not isfinite(value):
        raise SceneError(f"{name} = {value} is not finite")
    return value


def effect_value(name, parameter, value):
    try:
        return parameter.coerce(name.partition(".")[0], value)
    except ParameterError as error:
        raise SceneError(str(error)) from None
