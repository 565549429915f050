"""The command intake: torque, JointState and set-point commands checked, held and handed to
the simulator. May import: physics, node.params."""
