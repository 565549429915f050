"""arm_sim_ros: a planar two-link arm simulated with RK4, published as a ROS 2 node."""
