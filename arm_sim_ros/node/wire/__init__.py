"""ROS 2 messages on the wire: cyclonedds IDL types laid out as rmw_cyclonedds lays them,
JointState as CDR bytes, and what the wire refuses. May import: the base modules only."""
