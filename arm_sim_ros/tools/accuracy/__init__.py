"""`arm-sim accuracy`: the work-precision study, its independent reference and MuJoCo peer.
May import: physics, tools.arguments and progress."""
