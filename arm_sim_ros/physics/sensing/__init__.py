"""Sensing and actuation: what a controller meets on real hardware. The sensors' readings
(encoder counts, noise, offset, differenced velocity, sample rate, delay), seeded and
reproducible, and the control loop that has the drive read them and its commands act
command_delay later. May import: physics.model, stepping, effects."""
from .attach import Sensing, attach, check, drives, measures
from .sensors import Sensors, delay_steps

__all__ = ["Sensing", "Sensors", "attach", "check", "delay_steps", "drives", "measures"]
