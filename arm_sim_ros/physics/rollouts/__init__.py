"""Many runs: scenes run for a duration, each to an Outcome (its final state, books and
status), with their trajectories handed out chunk by chunk. May import: physics below batch."""
from .outcomes import OBSERVE_STEPS, Outcome
from .scenes import run_scenes

__all__ = ["OBSERVE_STEPS", "Outcome", "run_scenes"]
