"""`arm-sim run`'s outputs: the steps its recorders take, steps a stop may abandon, the bag
of an offline run. May import: physics, recording, node, tools.signals."""
