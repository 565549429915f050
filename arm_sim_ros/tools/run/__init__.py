"""`arm-sim run`'s outputs: rows held until confirmed, steps a stop may abandon, the bag
of an offline run. May import: physics, recording, node, tools.signals."""
