"""The node's ROS 2 interface as data: its name, topics and diagnostic levels.

Shared by the node, the recordings that write what the node publishes, and the tools
that talk to it; it imports nothing.
"""
NODE_NAME = "arm_sim"
JOINT_STATES_TOPIC = "joint_states"
# With `sensors` joint_states carries the readings, and the node publishes the truth here
# (sensor_msgs/JointState, same stamps); below: its absolute name in the root namespace.
TRUE_JOINT_STATES_TOPIC = "~/true_joint_states"
COMMAND_TOPIC = "joint_torque_commands"
JOINT_COMMANDS_TOPIC = "joint_commands"          # sensor_msgs/JointState efforts (ros2_control)
# Float64MultiArray [joint 1, joint 2] set-points of the servos, by field they set
SETPOINT_TOPICS = {"position": "position_commands", "velocity": "velocity_commands"}
DIAGNOSTICS_TOPIC = "/diagnostics"
JOINT_NAMES = ("shoulder_joint", "elbow_joint")   # as in urdf/two_link_arm.urdf

JOINT_STATE = "sensor_msgs/msg/JointState"
FLOAT64_MULTI_ARRAY = "std_msgs/msg/Float64MultiArray"
DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"
# What the node publishes and takes, by absolute name (as a bag of it lists them).
TRUE_JOINT_STATES = f"/{NODE_NAME}/true_joint_states"
NODE_TOPICS = {"/" + JOINT_STATES_TOPIC: JOINT_STATE,
               "/" + COMMAND_TOPIC: FLOAT64_MULTI_ARRAY,
               DIAGNOSTICS_TOPIC: DIAGNOSTIC_ARRAY}
SENSOR_TOPICS = {TRUE_JOINT_STATES: JOINT_STATE}     # published beside them with `sensors`

# Diagnostic levels, as diagnostic_msgs/DiagnosticStatus numbers them.
OK, WARN, ERROR = 0, 1, 2


def split_stamp(stamp_ns: int) -> tuple[int, int]:
    """builtin_interfaces/Time (sec, nanosec) of a stamp in nanoseconds."""
    return divmod(stamp_ns, 1_000_000_000)
