"""What the node's ROS services answer, transport-neutral: the Simulation Interfaces, the
SimulateSteps action and the rcl_interfaces parameter services. May import: node.params."""
