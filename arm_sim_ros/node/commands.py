"""Torque commands in: each checked, the good one held, dropped to zero on a timeout.

The command timeout is measured on the simulation clock: deterministic, and the same as wall
time at real_time_factor 1.
"""
from __future__ import annotations

import time
from math import isfinite

from ..interface import COMMAND_TOPIC

COMMAND_POLICIES = ("command", "command_gravity_compensation")
WARN_PERIOD = 1.0                 # seconds between repeated warnings of one kind


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


def refusal(data, torque_limit: float) -> str | None:
    """Why `data` is not a torque command [tau1, tau2] the node takes, or None."""
    try:
        values = [float(v) for v in data]
    except (TypeError, ValueError):
        return f"data {data!r} is not a list of numbers"
    if len(values) != 2:
        return f"data has {len(values)} values; expected 2 ([tau1, tau2] in N m)"
    for i, tau in enumerate(values):
        if not isfinite(tau):
            return f"tau{i + 1} = {tau} is not finite"
    for i, tau in enumerate(values):
        if abs(tau) > torque_limit:
            return f"|tau{i + 1}| = {abs(tau):g} N m exceeds torque_limit {torque_limit:g} N m"
    return None


def joint_state_refusal(names, position, velocity, effort, joint_names) -> str | None:
    """Why a JointState is not a torque command for these joints, or None."""
    if not effort:
        if position or velocity:
            return ("it carries no effort: the node is torque-driven, it does not follow "
                    "positions or velocities (use an effort controller)")
        return "it carries no effort"
    if len(effort) != len(names):
        return f"{len(names)} names but {len(effort)} efforts"
    unknown = [n for n in names if n not in joint_names]
    if unknown:
        return f"unknown joint {unknown[0]!r}; the joints are {', '.join(joint_names)}"
    if len(set(names)) != len(names):
        return "a joint is named twice"
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

    def take_joint_state(self, names, position, velocity, effort, joint_names, policy: str,
                         torque_limit: float, now: float):
        """A sensor_msgs/JointState command (as ros2_control's topic-based hardware interface
        sends them): efforts matched to joints by name, in any order; a joint it does not
        name keeps its held torque. (refusal reason or None, the new command or None).
        A NaN effort is ros2_control's unset command (its command interfaces hold NaN until
        a controller writes them): that joint is not commanded, which is no error."""
        reason = joint_state_refusal(list(names), list(position), list(velocity),
                                     list(effort), list(joint_names))
        if reason is not None:
            self.received += 1
            return self._refuse("refused joint commands", f"refused JointState command: "
                                f"{reason}", reason)
        commanded = [(name, tau) for name, tau in zip(names, effort) if tau == tau]   # not NaN
        if not commanded:
            return None, None
        command = list(self.value)
        for name, tau in commanded:
            command[list(joint_names).index(name)] = tau
        return self.take(command, policy, torque_limit, now)

    def _refuse(self, kind: str, text: str, reason: str):
        """Count a refused command and warn (rate-limited); (reason, no command)."""
        self.refused += 1
        self.warnings.warning(kind, f"{text} (refused so far: {self.refused})")
        return reason, None

    def timed_out(self, now: float, timeout: float) -> bool:
        """True when the held command has just expired and dropped to zero."""
        if timeout <= 0 or self.received_at is None or now - self.received_at < timeout - 1e-12:
            return False
        self.received_at = None
        self.timeouts += 1
        if self.value == (0.0, 0.0):
            return False
        self.value = (0.0, 0.0)
        self.log.warning(f"no torque command for {timeout:g} s: torque dropped to zero")
        return True
