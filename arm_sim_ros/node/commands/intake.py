"""Torque commands in: each checked, the good one held, dropped to zero on a timeout.

The command timeout is measured on the simulation clock: deterministic, and the same as wall
time at real_time_factor 1.
"""
from __future__ import annotations

import time
from math import isfinite

from ...interface import COMMAND_TOPIC

COMMAND_POLICIES = ("command", "command_gravity_compensation")
WARN_PERIOD = 1.0                 # seconds between repeated warnings of one kind
MAX_SETPOINT = 1e6                # rad, rad/s: as model.MAX_ANGLE (sin keeps digits)


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
# the target of its derivative term (a trajectory's velocity). A joint ignores the other
# fields: ros2_control's topic-based hardware sends every interface of every joint, and a
# controller deactivated leaves its last values in the interfaces it held.
TAKES = {"position": ("position", "velocity"), "velocity": ("velocity",), "effort": ("effort",)}
FIELDS = ("position", "velocity", "effort")
UNITS = {"position": "rad", "velocity": "rad/s", "effort": "N m"}


def joint_state_refusal(names, fields, joint_names) -> str | None:
    """Why a JointState (its `fields`: position, velocity, effort lists) is not a command
    for these joints whatever they take, or None."""
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
    return None


def value_refusal(joint: str, field: str, value: float, torque_limit: float) -> str | None:
    """Why a value a joint takes is refused, or None (NaN: unset, never refused)."""
    if value != value:
        return None
    if field == "effort":
        if not isfinite(value):
            return f"{joint} effort = {value} is not finite"
        if abs(value) > torque_limit:
            return (f"|{joint} effort| = {abs(value):g} N m exceeds torque_limit "
                    f"{torque_limit:g} N m")
        return None
    if not abs(value) <= MAX_SETPOINT:
        return f"{joint} {field} = {value} {UNITS[field]} is not finite or beyond {MAX_SETPOINT:g}"
    return None


class CommandIntake:
    """The held command and the counters the diagnostics report."""

    def __init__(self, log, warnings: RateLimitedLog):
        self.log, self.warnings = log, warnings
        self.received = self.refused = self.timeouts = 0
        self.last_refusal = "none"        # why the latest refused command was (diagnostics)
        self._said = set()                # (joint, interface, field) ignored, said once
        self.restart()

    def restart(self) -> None:
        self.value = (0.0, 0.0)
        self.received_at = None           # simulated time of the last good command
        self.setpoints = False            # a position or velocity set-point is commanded

    def take(self, data, policy: str, torque_limit: float, now: float):
        """[tau1, tau2] from joint_torque_commands: (refusal reason or None, the new command
        to apply or None). A joint that is not on effort holds it unused."""
        self.received += 1
        reason = refusal(data, torque_limit)
        if reason is not None:
            return self._refuse("refused commands", f"refused torque command: {reason}; holding "
                                f"{list(self.value)}", reason)
        if not self._follows(policy, COMMAND_TOPIC):
            return None, None
        return None, self._hold({0: float(data[0]), 1: float(data[1])}, now)

    def take_joint_state(self, names, fields, joint_names, interfaces, policy: str,
                         torque_limit: float, now: float):
        """A sensor_msgs/JointState command (as ros2_control's topic-based hardware interface
        sends them): values matched to joints by name, in any order, each joint taking the
        field(s) of its interface and ignoring the others; a joint it does not name keeps its
        held command. (refusal reason or None, new torque or None, set-points {(field, joint
        index): value}). A NaN is ros2_control's unset command (its command interfaces hold
        NaN until a controller writes them): that value is not commanded, which is no error.
        Only the values a joint takes are checked: never a held one, nor one it ignores."""
        self.received += 1
        names, joint_names = list(names), list(joint_names)
        fields = [list(f) for f in fields]
        reason = joint_state_refusal(names, fields, joint_names)
        if reason is None:
            taken, reason = self._taken(names, fields, joint_names, interfaces, torque_limit)
        if reason is not None:
            return (*self._refuse("refused joint commands", f"refused JointState command: "
                                  f"{reason}", reason), {})
        if not taken or not self._follows(policy, "joint_commands"):
            return None, None, {}
        efforts = {joint: v for (field, joint), v in taken.items() if field == "effort"}
        setpoints = {key: v for key, v in taken.items() if key[0] != "effort"}
        self._hold_setpoints(setpoints, now)
        return None, self._hold(efforts, now) if efforts else None, setpoints

    def _taken(self, names, fields, joint_names, interfaces, torque_limit: float):
        """({(field, joint index): value} the joints take, set (not NaN); the first refusal
        of one of them, or None)."""
        taken, reason = {}, None
        for field, values in zip(FIELDS, fields):
            for name, value in zip(names, values):
                joint = joint_names.index(name)
                if field not in TAKES[interfaces[joint]]:
                    self._ignored(name, interfaces[joint], field, value)
                    continue
                reason = reason or value_refusal(name, field, float(value), torque_limit)
                if value == value:
                    taken[(field, joint)] = float(value)
        return taken, reason

    def take_array(self, field: str, data, interfaces, policy: str, now: float):
        """[joint 1, joint 2] from position_commands or velocity_commands (NaN: that joint
        not commanded; a joint on another interface ignores it): (refusal reason or None,
        None, set-points {(field, joint): value})."""
        self.received += 1
        values, reason = _pair(data, f"{field}s in {UNITS[field]}")
        setpoints = {}
        for i, value in enumerate(values or ()):
            if field not in TAKES[interfaces[i]]:
                self._ignored(f"joint {i + 1}", interfaces[i], field, value)
                continue
            reason = reason or value_refusal(f"joint {i + 1}", field, value, 0.0)
            if value == value:
                setpoints[(field, i)] = value
        if reason is not None:
            return self._refuse("refused commands", f"refused {field} command: {reason}",
                                reason)[0], None, {}
        if not setpoints or not self._follows(policy, f"{field} set-points"):
            return None, None, {}
        self._hold_setpoints(setpoints, now)
        return None, None, setpoints

    def _follows(self, policy: str, what: str) -> bool:
        """Whether the policy follows commands; if not, a warning (rate-limited)."""
        if policy in COMMAND_POLICIES:
            return True
        self.warnings.warning("ignored commands", f"policy {policy!r} ignores {what}; set "
                              "policy to command to drive the arm")
        return False

    def _hold(self, efforts: dict, now: float) -> tuple:
        """{joint: torque} held from now (a joint not in it keeps its own); the command."""
        command = list(self.value)
        for joint, tau in efforts.items():
            command[joint] = tau
        if self.received_at is None:
            self.log.info(f"torque command {command} N m, held until the next one")
        self.value, self.received_at = tuple(command), now
        return self.value

    def _hold_setpoints(self, setpoints: dict, now: float) -> None:
        """Set-points held from now; the timeout starts again."""
        if not setpoints:
            return
        if not self.setpoints:
            self.log.info(f"set-points {dict(setpoints)} held until the next command")
        self.setpoints, self.received_at = True, now

    def _ignored(self, joint: str, interface: str, field: str, value) -> None:
        """A value in a field the joint does not take: ignored, said once at info (per
        joint, interface and field) when it is a value (not NaN)."""
        if value == value and (joint, interface, field) not in self._said:
            self._said.add((joint, interface, field))
            self.log.info(f"{joint} is on {interface} (servo.interface): it takes "
                          f"{' and '.join(TAKES[interface])} and ignores the {field} it is "
                          "sent (said once)")

    def _refuse(self, kind: str, text: str, reason: str):
        """Count a refused command and warn (rate-limited); (reason, no command)."""
        self.refused, self.last_refusal = self.refused + 1, reason
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
