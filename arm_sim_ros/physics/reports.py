"""What a simulator reports: a Sample (the arm and its energy books at one instant) and
Events (something it did that a person should hear about, each at its level)."""
from __future__ import annotations

from dataclasses import dataclass, field

# How loud each kind of event is, for every listener (the node's log, a recording's text
# log, arm-sim run): what the physics does by design is information (a switch, the
# tolerance taking more sub-steps, a chaotic motion becoming unpredictable); what costs
# accuracy or time is a warning (substepping, accuracy, saturation, servo); a refused step
# or broken books an error.
LEVELS = {"switch": "info", "substeps": "info", "unpredictable": "info",
          "books": "error", "fault": "error"}


@dataclass(frozen=True)
class Event:
    """Something the simulator did that a person should hear about (kind: substepping,
    substeps, unpredictable, accuracy, fault, saturation...), at its LEVELS level."""

    t: float
    kind: str
    message: str

    @property
    def level(self) -> str:
        return LEVELS.get(self.kind, "warning")


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
    extra: dict = field(default_factory=dict)      # the effects' extra states (i1, i2 ...)
    channels: dict = field(default_factory=dict)   # every channel by name
    inputs: float | None = None    # Σ input channels (None: the actuator work alone)
    losses: float | None = None    # Σ loss channels (None: the dissipated energy alone)
    measured: tuple | None = None  # with sensors: (q1, q2, q̇1, q̇2) as read (sensing/)

    @property
    def total(self) -> float:
        """E: kinetic plus every stored energy (gravity, springs, windings)."""
        return self.kinetic + self.potential

    @property
    def residual(self) -> float:
        """E(t) - E(0) - inputs + losses: zero for an exact integration."""
        inputs = self.work if self.inputs is None else self.inputs
        losses = self.dissipated if self.losses is None else self.losses
        return self.total - self.initial_energy - inputs + losses

    def as_dict(self) -> dict:
        return {"t": self.t, "q": list(self.q), "qd": list(self.qd), "tau": list(self.tau),
                **self.extra, "kinetic": self.kinetic, "potential": self.potential,
                "total": self.total, "work": self.work, "dissipated": self.dissipated,
                "channels": dict(self.channels), "residual": self.residual} | (
                    {} if self.measured is None else {"q_measured": list(self.measured[:2]),
                                                      "qd_measured": list(self.measured[2:])})
