"""Time, state and energy accounting for one arm: step() / run(duration) / reset().

Simulated time is always steps x step_size, never an accumulated sum, so late callers
cannot make it skip or drift.

At the stability limit (stability.py) a step is split into equal sub-steps, and a step
that would leave the finite numbers is refused: the last finite state is kept and
`fault` says why. Both are reported in `events`.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from math import isfinite

from . import model, stability
from .dynamics import build_dynamics
from .integrators import INTEGRATORS, compile_step
from .scene import Scene

EVENT_LOG_LENGTH = 100     # recent events kept; listeners see every one


@dataclass(frozen=True)
class Event:
    """Something the simulator did that a person should hear about (kind: substepping, fault)."""

    t: float
    kind: str
    message: str


@dataclass(frozen=True)
class Sample:
    """The arm and its energy books at one instant."""

    t: float
    q: tuple[float, float]
    qd: tuple[float, float]
    tau: tuple[float, float]
    kinetic: float
    potential: float
    work: float
    dissipated: float
    initial_energy: float

    @property
    def total(self) -> float:
        return self.kinetic + self.potential

    @property
    def residual(self) -> float:
        """E(t) - E(0) - W + dissipated: zero for an exact integration."""
        return self.total - self.initial_energy - self.work + self.dissipated

    def as_dict(self) -> dict:
        return {"t": self.t, "q": list(self.q), "qd": list(self.qd), "tau": list(self.tau),
                "kinetic": self.kinetic, "potential": self.potential, "total": self.total,
                "work": self.work, "dissipated": self.dissipated, "residual": self.residual}


class Simulator:
    def __init__(self, scene: Scene):
        self.scene = scene
        self.arm = scene.arm
        self.step_size = scene.step_size
        self.dynamics = build_dynamics(self.arm, scene.gravity, scene.damping, scene.policy,
                                       scene.constant_torque, scene.initial_positions)
        self.channels = self.dynamics.channels
        self._rhs = self.dynamics.function
        tableau = INTEGRATORS[scene.integrator]
        self._step = compile_step(tableau, len(self.channels), rtol=scene.rtol, atol=scene.atol)
        self.events: deque = deque(maxlen=EVENT_LOG_LENGTH)
        self.event_listeners: list = []     # callables(Event), e.g. the Rerun sink
        kinds = self.dynamics.channel_kinds
        self._inputs = [4 + i for i, kind in enumerate(kinds) if kind == "input"]
        self._losses = [4 + i for i, kind in enumerate(kinds) if kind == "loss"]
        self.reset()
        self._plan_substeps(tableau)

    def reset(self) -> None:
        s = self.scene
        self.state = (*s.initial_positions, *s.initial_velocities) + (0.0,) * len(self.channels)
        self.steps = 0
        self.fault = None            # why the latest refused step was refused, None if none
        self.refused_steps = 0
        self._refused_step = -1      # index of the latest refused step
        self.dynamics.command[:] = [0.0, 0.0]
        self.initial_energy = self.energy(self.state)

    @property
    def time(self) -> float:
        return self.steps * self.step_size

    def set_command(self, tau1: float, tau2: float) -> None:
        """The torque held by the `command` policies until the next call."""
        self.dynamics.command[0] = tau1
        self.dynamics.command[1] = tau2

    def _plan_substeps(self, tableau) -> None:
        """How many sub-steps keep damping stable at every elbow angle (1 = plain steps)."""
        self.stability_limit = stability.real_stability_limit(tableau)
        # h times the fastest real decay any effect adds (damping's d Lambda), at any pose.
        self.stability_ratio = self.step_size * sum(e.stiffness(self.arm)
                                                    for e in self.dynamics.active)
        adaptive = getattr(tableau, "adaptive", False)   # its own error control sub-steps
        self.substeps = (1 if adaptive else
                         stability.substeps_needed(self.stability_ratio, self.stability_limit))
        self._advance = stability.substepping(self._step, self.substeps)
        if self.substeps > 1:
            self._emit("substepping", (
                f"d h lambda_max = {self.stability_ratio:.4g} exceeds {tableau.name}'s stability "
                f"limit {self.stability_limit:.4g}: each {self.step_size:g} s step is taken as "
                f"{self.substeps} sub-steps"))

    @property
    def substeps_taken(self) -> int:
        """Sub-steps run since reset in steps that had to be split (0 while plain RK4 is stable)."""
        return self.steps * self.substeps if self.substeps > 1 else 0

    @property
    def holding(self) -> bool:
        """True while the latest step was refused and the state is the last finite one."""
        return self.refused_steps > 0 and self._refused_step == self.steps - 1

    def step(self) -> None:
        try:
            y = self._advance(self._rhs, self.state, self.step_size)
        except (ValueError, OverflowError, ZeroDivisionError) as error:  # cos(inf), inf ** 2
            self._refuse(f"cannot be taken: {error}")
        else:
            total = sum(y)
            if total - total == 0.0 or all(isfinite(v) for v in y):  # inf - inf, NaN are NaN
                self.state = y
            else:
                names = ("q1", "q2", "qd1", "qd2") + self.channels
                self._refuse("would make " + ", ".join(
                    f"{n} = {v}" for n, v in zip(names, y) if not isfinite(v)))
        self.steps += 1

    def _refuse(self, why: str) -> None:
        self.fault = (f"the step to t = {(self.steps + 1) * self.step_size:.6g} s {why}; "
                      "holding the last finite state")
        if not self.holding:            # the first of a run of refusals
            self._emit("fault", self.fault)
        self._refused_step = self.steps
        self.refused_steps += 1

    def _emit(self, kind: str, message: str) -> None:
        event = Event(self.time, kind, message)
        self.events.append(event)
        for listener in self.event_listeners:
            listener(event)

    def energies(self, state) -> tuple[float, float]:
        """(kinetic, potential); NaN where they cannot be evaluated (angles near 1e308
        make sin fail), so a held absurd state is reported rather than crashing."""
        q, qd = state[0:2], state[2:4]
        try:
            return (model.kinetic_energy(self.arm, q, qd),
                    sum((e.stored_energy(self.arm, q) for e in self.dynamics.active), 0.0))
        except ValueError:
            return float("nan"), float("nan")

    def energy(self, state) -> float:
        return sum(self.energies(state))

    def books(self, state) -> tuple[float, float]:
        """(energy put in, energy lost) carried in a state's channels: actuator work and
        dissipated energy today; 0 where no effect has such a channel."""
        return (sum((state[i] for i in self._inputs), 0.0),
                sum((state[i] for i in self._losses), 0.0))

    def residual(self) -> float:
        work, dissipated = self.books(self.state)
        return self.energy(self.state) - self.initial_energy - work + dissipated

    def sample(self) -> Sample:
        y = self.state
        q, qd = (y[0], y[1]), (y[2], y[3])
        kinetic, potential = self.energies(y)
        work, dissipated = self.books(y)
        return Sample(t=self.time, q=q, qd=qd, tau=tuple(self.dynamics.applied_torque(q)),
                      kinetic=kinetic, potential=potential, work=work, dissipated=dissipated,
                      initial_energy=self.initial_energy)

    def run(self, duration: float, on_step=None) -> float:
        """Advance by `duration` (a whole number of steps); return the largest |residual|
        seen at any step, which for an unpowered undamped arm is the energy drift."""
        steps = self.scene.steps_for(duration, self.step_size)
        largest = 0.0
        for _ in range(steps):
            self.step()
            largest = max(largest, abs(self.residual()))
            if on_step is not None:
                on_step(self)
        return largest
