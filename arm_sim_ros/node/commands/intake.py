"""Torque commands in: each checked, the good one held, dropped to zero on a timeout.

The command timeout is measured on the simulation clock: deterministic, and the same as wall
time at real_time_factor 1.
"""
from __future__ import annotations

import time
from math import isfinite

from ...interface import COMMAND_TOPIC
from ...physics.model import MAX_ANGLE

COMMAND_POLICIES = ("command", "command_gravity_compensation")
WARN_PERIOD = 1.0                 # seconds between repeated warnings of one kind
MAX_SETPOINT = MAX_ANGLE          # rad, rad/s: 1e6, where sin still keeps digits


class RateLimitedLog:
    """At most one line per kind per WARN_PERIOD; the next says how many of that kind (for
    any reason) were held back."""

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
        self.log.warning(text + (f" ({held} more {kind} since the last warning)" if held else ""))


def _pair(data, what: str):
    """([value 1, value 2], None), or (None, why `data` is not two numbers)."""
    try:
        values = [float(v) for v in data]
    except (TypeError, ValueError):
        return None, f"data {data!r} is not a list of numbers"
    if len(values) != 2:
        return None, f"data has {len(values)} values; expected 2 ({what})"
    return values, None


def refusal(data, torque_limit: float) -> str | None:
    """Why `data` is not a torque command [tau1, tau2] the node takes, or None."""
    values, why = _pair(data, "[tau1, tau2] in N m")
    if why is not None:
        return why
    for i, tau in enumerate(values):
        if not isfinite(tau):
            return f"tau{i + 1} = {tau} is not finite"
    for i, tau in enumerate(values):
        if abs(tau) > torque_limit:
            return f"|tau{i + 1}| = {abs(tau):g} N m exceeds torque_limit {torque_limit:g} N m"
    return None


# What each interface takes from a command (servo.py): a position joint also takes a velocity,
# the target of its derivative term (a trajectory's velocity).
TAKES = {"position": ("position", "velocity"), "velocity": ("velocity",), "effort": ("effort",)}
FIELDS = ("position", "velocity", "effort")


def joint_state_refusal(names, fields, joint_names, interfaces) -> str | None:
    """Why a JointState (its `fields`: position, velocity, effort lists) is not a command
    for these joints, or None. NaN is an unset value (ros2_control's), never refused."""
    given = {field: values for field, values in zip(FIELDS, fields) if values}
    if not given:
        return "it carries no position, velocity or effort"
    for field, values in given.items():
        if len(values) != len(names):
            return f"{len(names)} names but {len(values)} {field}s"
    unknown = [n for n in names if n not in joint_names]
    if unknown:
        return f"unknown joint {unknown[0]!r}; the joints are {', '.join(joint_names)}"
    if len(set(names)) != len(names):
        return "a joint is named twice"
    for field, values in given.items():
        for name, value in zip(names, values):
            interface = interfaces[list(joint_names).index(name)]
            if value == value and field not in TAKES[interface]:   # set (not NaN)
                return _not_taken(name, interface, field)
    return None


def _not_taken(joint: str, interface: str, field: str) -> str:
    if interface == "effort" and field != "effort":
        return (f"{joint} takes effort only: the node is torque-driven there, it does not "
                f"follow {field}s (set servo.interface to {field} for it, or use an effort "
                "controller)")
    return f"{joint} is a {interface} joint: it does not take {field} (servo.interface)"


def setpoint_refusal(field: str, data, interfaces) -> str | None:
    """Why `data` is not a [joint 1, joint 2] `field` command, or None (NaN: not set)."""
    values, why = _pair(data, f"{field}s in {UNITS[field]}")
    if why is not None:
        return why
    for i, value in enumerate(values):
        if value == value and field not in TAKES[interfaces[i]]:
            return _not_taken(f"joint {i + 1}", interfaces[i], field)
    return None


UNITS = {"position": "rad", "velocity": "rad/s"}


def out_of_range(setpoints: dict) -> str | None:
    """Why a set-point {(field, joint): value} cannot be followed (±inf or beyond
    MAX_SETPOINT), or None: checked where every topic's set-points come in."""
    for (field, joint), value in setpoints.items():
        if not abs(value) <= MAX_SETPOINT:
            return (f"{field} {joint + 1} = {value} {UNITS[field]} is not finite or beyond "
                    f"{MAX_SETPOINT:g}")
    return None


class CommandIntake:
    """The held command and the counters the diagnostics report."""

    def __init__(self, log, warnings: RateLimitedLog):
        self.log, self.warnings = log, warnings
        self.received = self.refused = self.timeouts = 0
        self.restart()

    def restart(self) -> None:
        self.value = (0.0, 0.0)
        self.received_at = None           # simulated time of the last good command
        self.setpoints = False            # a position or velocity set-point is commanded

    def take(self, data, policy: str, torque_limit: float, now: float):
        """(refusal reason or None, the new command to apply or None)."""
        self.received += 1
        reason = refusal(data, torque_limit)
        if reason is not None:
            return self._refuse("refused commands", f"refused torque command: {reason}; holding "
                                f"{list(self.value)}", reason)
        if policy not in COMMAND_POLICIES:
            self.warnings.warning("ignored commands", f"policy {policy!r} ignores {COMMAND_TOPIC}; "
                                  "set policy to command to drive the arm")
            return None, None
        if self.received_at is None:
            self.log.info(f"torque command {list(data)} N m, held until the next one")
        self.value, self.received_at = (float(data[0]), float(data[1])), now
        return None, self.value

    def take_joint_state(self, names, fields, joint_names, interfaces, policy: str,
                         torque_limit: float, now: float):
        """A sensor_msgs/JointState command (as ros2_control's topic-based hardware interface
        sends them): values matched to joints by name, in any order; a joint it does not
        name keeps its held command. (refusal reason or None, new torque or None, set-points
        {(field, joint index): value}). A NaN is ros2_control's unset command (its command
        interfaces hold NaN until a controller writes them): that value is not commanded,
        which is no error."""
        names = list(names)
        reason = joint_state_refusal(names, [list(f) for f in fields], list(joint_names),
                                     interfaces)
        if reason is not None:
            self.received += 1
            return (*self._refuse("refused joint commands", f"refused JointState command: "
                                  f"{reason}", reason), {})
        index = {name: list(joint_names).index(name) for name in names}
        position, velocity, effort = (list(f) for f in fields)
        setpoints = {(field, index[name]): v for field, values in (("position", position),
                                                                     ("velocity", velocity))
                     for name, v in zip(names, values) if v == v}
        if setpoints:
            reason, setpoints = self.take_setpoints(setpoints, policy, now)
            if reason is not None:
                self.received += 1
                return reason, None, {}
        commanded = [(index[name], tau) for name, tau in zip(names, effort) if tau == tau]
        if not commanded:
            if setpoints:
                self.received += 1
            return None, None, setpoints
        command = list(self.value)
        for joint, tau in commanded:
            command[joint] = tau
        return (*self.take(command, policy, torque_limit, now), setpoints)

    def take_array(self, field: str, data, interfaces, policy: str, now: float):
        """[joint 1, joint 2] from position_commands or velocity_commands (NaN: that joint
        not commanded): (refusal reason or None, None, set-points {(field, joint): value})."""
        self.received += 1
        reason = setpoint_refusal(field, data, interfaces)
        if reason is not None:
            return self._refuse("refused commands", f"refused {field} command: {reason}",
                                reason)[0], None, {}
        reason, setpoints = self.take_setpoints(
            {(field, i): float(v) for i, v in enumerate(data) if v == v}, policy, now)
        return reason, None, setpoints

    def take_setpoints(self, setpoints: dict, policy: str, now: float):
        """(None, `setpoints`) when the policy follows commands, else (None, {}) and a
        warning; the timeout starts again. Every topic's set-points come in here, so each is
        range-checked here: (reason, {}) refused."""
        reason = out_of_range(setpoints)
        if reason is not None:
            return self._refuse("refused commands", f"refused set-point command: {reason}",
                                reason)[0], {}
        if policy not in COMMAND_POLICIES:
            self.warnings.warning("ignored commands", f"policy {policy!r} ignores set-point "
                                  "commands; set policy to command to drive the servos")
            return None, {}
        if not self.setpoints and setpoints:
            self.log.info(f"set-points {dict(setpoints)} held until the next command")
        self.setpoints, self.received_at = bool(setpoints) or self.setpoints, now
        return None, setpoints

    def _refuse(self, kind: str, text: str, reason: str):
        """Count a refused command and warn (rate-limited); (reason, no command)."""
        self.refused += 1
        self.warnings.warning(kind, f"{text} (refused so far: {self.refused})")
        return reason, None

    def timed_out(self, now: float, timeout: float) -> bool:
        """True when the held command has just expired: torque dropped to zero, and any
        servo set-point commanded given up (the node then holds the servos where they are)."""
        if timeout <= 0 or self.received_at is None or now - self.received_at < timeout - 1e-12:
            return False
        self.received_at = None
        self.timeouts += 1
        if self.value == (0.0, 0.0) and not self.setpoints:
            return False
        self.log.warning(f"no command for {timeout:g} s: servos hold where they are, velocity "
                         "joints stop" if self.setpoints else
                         f"no torque command for {timeout:g} s: torque dropped to zero")
        self.value, self.setpoints = (0.0, 0.0), False
        return True
