"""Trust: the error estimates (local, global along the shadow), the step-size controller and
the divergence guard. May import: physics.model, stepping."""
