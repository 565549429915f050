"""Time, state and energy accounting for one arm: step() / run(duration) / reset().

Simulated time is always steps x step_size, never an accumulated sum, so late callers
cannot make it skip or drift.
"""
from __future__ import annotations

from dataclasses import dataclass

from . import model
from .dynamics import build_dynamics
from .integrators import INTEGRATORS, compile_step
from .scene import Scene


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
        self._step = compile_step(INTEGRATORS[scene.integrator], len(self.channels))
        self._work_index = 4 + self.channels.index("work") if "work" in self.channels else None
        self._dissipated_index = (4 + self.channels.index("dissipated")
                                  if "dissipated" in self.channels else None)
        self.reset()

    def reset(self) -> None:
        s = self.scene
        self.state = (*s.initial_positions, *s.initial_velocities) + (0.0,) * len(self.channels)
        self.steps = 0
        self.dynamics.command[:] = [0.0, 0.0]
        self.initial_energy = self.energy(self.state)

    @property
    def time(self) -> float:
        return self.steps * self.step_size

    def set_command(self, tau1: float, tau2: float) -> None:
        """The torque held by the `command` policies until the next call."""
        self.dynamics.command[0] = tau1
        self.dynamics.command[1] = tau2

    def step(self) -> None:
        self.state = self._step(self._rhs, self.state, self.step_size)
        self.steps += 1

    def energy(self, state) -> float:
        q, qd = state[0:2], state[2:4]
        return (model.kinetic_energy(self.arm, q, qd)
                + model.potential_energy(self.arm, q, self.scene.gravity))

    def residual(self) -> float:
        y = self.state
        work = y[self._work_index] if self._work_index is not None else 0.0
        dissipated = y[self._dissipated_index] if self._dissipated_index is not None else 0.0
        return self.energy(y) - self.initial_energy - work + dissipated

    def sample(self) -> Sample:
        y = self.state
        q, qd = (y[0], y[1]), (y[2], y[3])
        return Sample(
            t=self.time, q=q, qd=qd, tau=tuple(self.dynamics.applied_torque(q)),
            kinetic=model.kinetic_energy(self.arm, q, qd),
            potential=model.potential_energy(self.arm, q, self.scene.gravity),
            work=y[self._work_index] if self._work_index is not None else 0.0,
            dissipated=y[self._dissipated_index] if self._dissipated_index is not None else 0.0,
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
