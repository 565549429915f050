"""The arm_sim node: its core with no transport, and thin transports (rclpy, dds).
May import: physics, recording, the base modules."""
