"""A payload: a point mass m at the tip of link 2 (distance l₂ from the elbow along link 2).

It changes the inertia and gravity terms exactly, by folding the mass into link 2
(ArmParameters.with_payload), so it adds no code to f. What it adds is a channel,
`payload_exchange`: a grasp at run time (Simulator.set_payload) keeps the generalized
momentum M(q) q̇ (an inelastic grasp of a mass at rest), a release keeps q̇, and the energy
that changes hands (kinetic and potential) is booked there so the balance still closes.

Scene: `payload: {mass: m}` (kg).
"""
from __future__ import annotations

from .base import Channel, Effect, Parameter


class Payload(Effect):
    name = "payload"
    parameters = (Parameter("mass", "float", "kg", "non-negative",
                            description="point mass held at the tip of link 2"),)

    def __init__(self, mass: float):
        self.mass = mass

    def channels(self):
        # Changes only at a grasp or release, between steps: its rate is zero.
        return (Channel("payload_exchange", "0.0", "input"),)
