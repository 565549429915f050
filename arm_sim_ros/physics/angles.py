"""Angles in degrees, by one rule: every key whose unit is an angle (rad, or rad per count)
takes a number of degrees written `90deg` wherever a value is given (`--set`, a scene file, a
node parameter); every other key refuses `deg`, naming those that take it. scene.py applies
it with its own error and parser (`refuse`, `parse`)."""
from __future__ import annotations

from math import radians

from . import sensing
from .effects import MAPPING_EFFECTS

ANGLE_UNITS = ("rad", "rad per count")
ANGLE_KEYS = ("initial_positions",) + tuple(
    f"{effect}.{parameter.name}"
    for effect, mapping in sorted((MAPPING_EFFECTS | {"sensors": sensing.Sensors}).items())
    for parameter in mapping.parameters if parameter.unit in ANGLE_UNITS)


def degrees(key: str, text: str, refuse) -> float:
    """`text`, a number ending in deg, in radians; `refuse(message)` is raised for a key (or
    its element `key[i]`) that is no angle."""
    if key.partition("[")[0] not in ANGLE_KEYS:
        raise refuse(f"{key}={text!r}: only angles take deg, the keys in rad: "
                     f"{', '.join(ANGLE_KEYS)}")
    return radians(float(text[:-3]))


def in_radians(key: str, value, parse, refuse):
    """`value` of `key` with each number written in degrees (`90deg`: text, from YAML or
    ROS 2) in radians; text with commas is read by `parse(key, text)`, as --set reads it."""
    if isinstance(value, str) and "deg" in value and key in ANGLE_KEYS:
        return parse(key, value)
    if isinstance(value, (list, tuple)):
        return type(value)(in_radians(f"{key}[{i}]", v, parse, refuse)
                           for i, v in enumerate(value))
    if isinstance(value, str) and value.strip().endswith("deg"):
        try:
            return degrees(key, value.strip(), refuse)
        except ValueError as error:
            if isinstance(error, refuse):
                raise
            raise refuse(f"{key}={value!r}: expected a number of degrees, like 90deg") from None
    return value
