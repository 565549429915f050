"""ros2_control beside the node (`arm_sim_controllers`): the command interface each joint's
active controller claims, followed into the node's servo.interface; the controllers started
once the hardware has read the node's first JointState. The rules need no ROS (claims.py);
the node that applies them is rclpy's (follower.py). May import: interface, node.params."""
