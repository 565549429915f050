"""Stepping: Runge-Kutta methods as data and the stability plan of their sub-steps.
May import: physics.model."""
