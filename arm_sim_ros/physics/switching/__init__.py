"""Switching: non-smooth effects (friction, joint limits, clamps) switched at events located
inside the step on dense output. May import: physics.model, stepping, effects, dynamics."""
