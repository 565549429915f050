"""Tools on the live ROS 2 wire with no ROS installed: record, send-torque and a Simulation
Interfaces client. May import: node.wire, node.services, recording.bags, tools.signals."""
