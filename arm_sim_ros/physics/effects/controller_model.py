"""The controller's own model of the arm: what the gravity-compensating policies believe.

Scene: `controller_model: {gravity, link_masses, com_distances, link_lengths, payload_mass}`,
each optional; an unnamed key is the true arm's value. With it, the compensation torque is
computed from the believed gravity coefficients (its own lines, GC1/GC2), so a controller
compensating for the wrong payload lets the arm sag exactly as the physics says.
"""
from __future__ import annotations

from dataclasses import replace

from .. import model
from .base import Effect, Parameter


class ControllerModel(Effect):
    name = "controller_model"
    parameters = (
        Parameter("gravity", "float", "m/s^2", "non-negative", default=None,
                  description="gravity the controller compensates (default: the true one)"),
        Parameter("link_masses", "pair", "kg", "positive", default=None,
                  description="link masses it believes (default: the true ones)"),
        Parameter("com_distances", "pair", "m", default=None,
                  description="joint-to-COM distances it believes (default: the true ones)"),
        Parameter("link_lengths", "pair", "m", "positive", default=None,
                  description="link lengths it believes (default: the true ones)"),
        Parameter("payload_mass", "float", "kg", "non-negative", default=None,
                  description="payload it believes held (default: the true one)"),
    )

    def __init__(self, true_arm, true_gravity: float, true_payload: float = 0.0, **believed):
        """`true_arm` without its payload; `believed` the keys the controller gets wrong."""
        self.gravity = believed.pop("gravity", None)
        self.gravity = true_gravity if self.gravity is None else self.gravity
        payload = believed.pop("payload_mass", None)
        payload = true_payload if payload is None else payload
        # Only its gravity is ever used: inertias of 1 kg m^2 keep a believed COM on the
        # elbow axis from making a mass matrix nobody uses singular (refused by ArmParameters).
        arm = replace(true_arm, com_inertias=(1.0, 1.0),
                      **{k: v for k, v in believed.items() if v is not None})
        self.arm = arm.with_payload(payload)

    def constants(self, arm) -> dict:
        k1, k2 = self.arm.gravity_coefficients
        return {"GC1": self.gravity * k1, "GC2": self.gravity * k2}

    def terms(self) -> list[str]:
        return ["gc2 = GC2 * cos(q1 + q2)",
                "gc1 = GC1 * cos(q1) + gc2"]

    def gravity_torque(self, q):
        return model.gravity_torque(self.arm, q, self.gravity)
