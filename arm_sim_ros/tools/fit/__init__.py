"""`arm-sim fit` and `arm-sim excite`: scene keys identified from a recording.
May import: physics, recording, tools.arguments and progress."""
