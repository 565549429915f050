"""Effort and voltage clamps as modes, for events.py.

A clamp whose request depends on the state (a gravity-compensating policy's torque, the
driver voltage it asks for) passes it (mode 0) or holds ±limit (mode 1/-1), per joint:
the fifth entry of a mode is (effort 1, effort 2, voltage 1, voltage 2). Within a mode the
right-hand side is smooth (effects/effort_limits.py, effects/motors.py write each mode's
lines); the switching functions request − limit etc. end it, and events.py locates that
inside the step like a friction switch. After any switch the clamps' modes are found again
from the state (effort first: the voltage asked for is the clamped torque's), which gives
exactly the mode whose switching functions hold there.

A request constant within a step (constant, frozen, command) makes no switching clamp: it
keeps MIN/MAX, constant within the step. A command changed between steps (the
command_gravity_compensation policy) has its clamps found again at the step's start.
"""
from __future__ import annotations

INF = float("inf")
KINDS = ("effort", "voltage")
PASSING = (0, 0, 0, 0)


class Clamps:
    """The switching clamps of a scene's dynamics (None from `of` without any)."""

    def __init__(self, effort, driver, command):
        self.limits = ((*effort.limits,) if effort is not None else (INF, INF)) + (
            (*driver.voltage_limit,) if driver is not None else (INF, INF))
        self.requests = (("ta1", "ta2") if effort is not None else ("0.0", "0.0")) + (
            ("va1", "va2") if driver is not None else ("0.0", "0.0"))
        self.parts = [part for part, on in ((0, effort), (2, driver)) if on is not None]
        self.command, self.seen = command, list(command)

    @staticmethod
    def of(dynamics) -> Clamps | None:
        effects = {e.name: e for e in dynamics.active if e.switching}
        effort, driver = effects.get("effort_limits"), effects.get("motors")
        if effort is None and driver is None:
            return None
        return Clamps(effort, driver, dynamics.command)

    def initial(self, mode) -> tuple:
        """`mode` (codes and zones) with every clamp passing, to be found by `found`."""
        return (*mode[:4], PASSING)

    def found(self, y, mode, requests_of) -> tuple:
        """`mode` with the clamps' modes the state y calls for; `requests_of(mode)` is the
        mode's requests function (ta1, ta2, va1, va2 there)."""
        self.seen = list(self.command)
        clamps = list(mode[4])
        for part in self.parts:
            values = requests_of((*mode[:4], tuple(clamps)))(*y)   # y: q, q̇, extra
            for k in (part, part + 1):
                x, limit = values[k], self.limits[k]
                clamps[k] = 1 if x > limit else -1 if x < -limit else 0
        return (*mode[:4], tuple(clamps))

    def stale(self) -> bool:
        """The command changed since the modes were found (it jumps between steps)."""
        return self.command != self.seen

    @staticmethod
    def kind(kind: str, joint: int, after) -> str:
        """What the switch of clamp `kind` of `joint` did, as switch_events counts it:
        effort_saturation, effort_release, voltage_saturation, voltage_release."""
        k = KINDS.index(kind) * 2 + joint
        return f"{kind}_{'saturation' if after[4][k] else 'release'}"
