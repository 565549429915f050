"""Transports that carry the arm_sim node core onto a middleware.

`rclpy` is real ROS 2 (needs a sourced Jazzy); `dds` is cyclonedds from PyPI, wire-compatible
with rmw_cyclonedds, for machines without ROS. Modules are imported only when chosen.
"""
from __future__ import annotations

TRANSPORTS = ("rclpy", "dds")


class TransportUnavailable(ValueError):
    """The transport asked for cannot run here; the message says what to do instead."""


def rclpy_available() -> bool:
    try:  # a found but broken rclpy (wrong Python, ROS not sourced) counts as absent
        import rclpy  # noqa: F401
    except Exception:
        return False
    return True


def choose(name: str = "auto") -> str:
    """`auto` means rclpy when it can be imported, else dds."""
    if name == "auto":
        return "rclpy" if rclpy_available() else "dds"
    if name not in TRANSPORTS:
        raise TransportUnavailable(f"unknown transport {name!r}; choose auto, {', '.join(TRANSPORTS)}")
    if name == "rclpy" and not rclpy_available():
        raise TransportUnavailable("transport rclpy needs ROS 2 Jazzy sourced (rclpy cannot be imported); "
                         "use --transport dds")
    return name
