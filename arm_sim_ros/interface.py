"""The node's ROS 2 interface as data: its name, topics, services, action and diagnostic levels.

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
CLOCK = "rosgraph_msgs/msg/Clock"

# Everything the node serves, by the name it resolves (relative: in the node's namespace;
# `~/`: under the node's own name), with its type and what it carries. The reference
# (docs/reference/node.md) is made from these, and a test holds the dds node on the wire to
# exactly them.
PUBLISHES = {
    JOINT_STATES_TOPIC: (JOINT_STATE, "every tick: position (rad, unwrapped), velocity "
                         "(rad/s) and effort (the torque the joints receive, N m), stamped "
                         "with simulated time; with `sensors`, position and velocity as read"),
    "/clock": (CLOCK, "simulated time, every tick, equal to the JointState stamps "
               "(publish_clock)"),
    DIAGNOSTICS_TOPIC: (DIAGNOSTIC_ARRAY, "1 Hz: refused commands, real-time factor, energy "
                        "balance residual, late ticks, the error estimate"),
    "/parameter_events": ("rcl_interfaces/msg/ParameterEvent", "every accepted parameter change"),
    TRUE_JOINT_STATES_TOPIC: (JOINT_STATE, "with `sensors` only (from the first tick they are "
                              "set): the state itself, same stamps, while joint_states "
                              "carries the readings"),
}
WITH_SENSORS = (TRUE_JOINT_STATES_TOPIC,)    # published only while the scene has sensors
SUBSCRIBES = {
    COMMAND_TOPIC: (FLOAT64_MULTI_ARRAY, "[tau1, tau2] N m, held until the next one; zero "
                    "after command_timeout"),
    JOINT_COMMANDS_TOPIC: (JOINT_STATE, "commands by joint name, each joint taking the field "
                           "of its interface (effort N m; position rad or velocity rad/s for "
                           "a joint servo): what ros2_control's topic-based hardware sends"),
    SETPOINT_TOPICS["position"]: (FLOAT64_MULTI_ARRAY, "[q1, q2] rad: set-points of the "
                                  "position servos"),
    SETPOINT_TOPICS["velocity"]: (FLOAT64_MULTI_ARRAY, "[qd1, qd2] rad/s: set-points of the "
                                  "velocity servos"),
}
PARAMETER_SERVICES = ("describe_parameters", "get_parameter_types", "get_parameters",
                      "list_parameters", "set_parameters", "set_parameters_atomically")
SIMULATION = "simulation_interfaces/srv/"
SERVICES = {
    "~/reset": ("std_srvs/srv/Trigger", "restart the scene (stamps keep counting)"),
    **{f"~/{name}": (f"rcl_interfaces/srv/{name.title().replace('_', '')}",
                     "the node's parameters, as every ROS 2 node serves them")
       for name in PARAMETER_SERVICES},
    "get_simulator_features": (SIMULATION + "GetSimulatorFeatures", "what this simulator "
                               "supports (ROS 2 Simulation Interfaces)"),
    "get_simulation_state": (SIMULATION + "GetSimulationState", "playing, paused or stopped"),
    "set_simulation_state": (SIMULATION + "SetSimulationState", "play, pause or stop"),
    "step_simulation": (SIMULATION + "StepSimulation", "N ticks while paused"),
    "reset_simulation": (SIMULATION + "ResetSimulation", "the scene from its start"),
}
ACTIONS = {
    "simulate_steps": ("simulation_interfaces/action/SimulateSteps", "N ticks while paused, "
                       "with feedback after each"),
}
# Every topic the node publishes or takes, by its absolute name in the root namespace, with
# its one type: a tool asked to put another type on one of these names refuses (wrong_type).
KNOWN_TOPICS = {"/" + name.lstrip("/"): kind
                for name, (kind, _) in (PUBLISHES | SUBSCRIBES).items()}


def wrong_type(topic: str, message_type: str) -> str | None:
    """Why `message_type` cannot go on `topic` (a relative name as in the root namespace),
    or None: one of the node's topics carries its own type, and no other."""
    name = "/" + topic.lstrip("/")
    known = KNOWN_TOPICS.get(name)
    if known is None or known == message_type:
        return None
    return f"{name} carries {known}, not {message_type}"


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
