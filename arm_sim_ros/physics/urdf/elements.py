"""The elements of a URDF as numbers: names, masses, origins, axes; SceneError (one line)
naming the element for anything that is not."""
from __future__ import annotations

from math import isfinite, sqrt

import numpy as np

from ..model import brief
from ..scene import SceneError


def joint_name(joint) -> str:
    return joint.get("name") or "(unnamed joint)"


def child_link(joint) -> str:
    return joint.find("child").get("link")


def link_mass(link):
    element = link.find("inertial/mass")
    return None if element is None else read_number(element, "value", f"link {link.get('name')} <mass>")


def read_number(element, key, where, default=None) -> float:
    text = element.get(key)
    if text is None:
        if default is None:
            raise SceneError(f"URDF: {where} has no {key}")
        return default
    try:
        value = float(text)
    except ValueError:
        raise SceneError(f"URDF: {where} {key}={brief(text)} is not a number") from None
    if not isfinite(value):
        raise SceneError(f"URDF: {where} {key}={brief(text)} is not finite")
    return value


def read_vector(element, key, where, default) -> np.ndarray:
    text = element.get(key) if element is not None else None
    if text is None:
        return np.array(default, dtype=float)
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) != 3 or not all(isfinite(v) for v in values):
        raise SceneError(f"URDF: {where} {key}={brief(text)} is not three finite numbers")
    return np.array(values)


def element_origin(element, where):
    """(rotation, translation) of an element's <origin>: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    found = element.find("origin")
    xyz = read_vector(found, "xyz", where + " <origin>", (0.0, 0.0, 0.0))
    roll, pitch, yaw = read_vector(found, "rpy", where + " <origin>", (0.0, 0.0, 0.0))
    return rpy_rotation(roll, pitch, yaw), xyz


def rpy_rotation(roll, pitch, yaw) -> np.ndarray:
    if not (roll or pitch or yaw):
        return np.eye(3)                   # exact: generated URDFs read back bit for bit
    cr, sr, cp, sp, cy, sy = (np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch),
                              np.cos(yaw), np.sin(yaw))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def joint_axis(joint) -> np.ndarray:
    """The joint's unit axis in its child's frame (URDF's default: x)."""
    axis = read_vector(joint.find("axis"), "xyz", f"joint {joint_name(joint)} <axis>", (1.0, 0.0, 0.0))
    norm = sqrt(float(axis @ axis))
    if not norm > 0:
        raise SceneError(f"URDF: joint {joint_name(joint)} has a zero <axis>")
    return axis / norm
