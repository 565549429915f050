"""The arm_sim node driven by ros2_control: controller_manager with the topic-based hardware
interface (urdf/two_link_arm.ros2_control.xml), a joint_state_broadcaster, every controller of
config/ros2_controllers.yaml (the one the `controller` argument picks active, the others
loaded and inactive, ready to switch to), arm_sim_controllers and robot_state_publisher.

    ros2 launch arm_sim_ros arm_sim_ros2_control.launch.py                  # position JTC
    ros2 action send_goal /position_trajectory_controller/follow_joint_trajectory \
        control_msgs/action/FollowJointTrajectory "{trajectory: {joint_names: \
        [shoulder_joint, elbow_joint], points: [{positions: [0.8, -0.4], \
        time_from_start: {sec: 2}}]}}"
    ros2 control switch_controllers --deactivate position_trajectory_controller \
        --activate forward_velocity_controller
    ros2 topic pub --once /forward_velocity_controller/commands \
        std_msgs/msg/Float64MultiArray "{data: [0.3, -0.2]}"
    ros2 launch arm_sim_ros arm_sim_ros2_control.launch.py controller:=effort
    ros2 launch arm_sim_ros arm_sim_ros2_control.launch.py controller:=velocity
    ros2 launch arm_sim_ros arm_sim_ros2_control.launch.py use_sim_time:=true lockstep:=true
    ros2 launch arm_sim_ros arm_sim_ros2_control.launch.py transport:=dds

The arm starts held: the default scene servo_hold holds its initial pose with joint servos
(position, velocity) or gravity feed-forward (effort: policy command_gravity_compensation),
until a controller commands it. Each joint follows the command interface its active
controller claims: `arm_sim_controllers follow` sets the node's servo.interface at every
switch (the topic-based hardware sends every interface, claimed or not), so controllers
switch live in any order. The controllers are activated once the hardware has read the
node's first JointState (`arm_sim_controllers wait`), so none starts from NaN.
Needs ros2_control, ros2_controllers (joint_trajectory_controller, forward_command_controller,
joint_state_broadcaster) and topic_based_hardware_interfaces.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, LogInfo, OpaqueFunction, RegisterEventHandler
from launch.conditions import IfCondition
from launch.event_handlers import OnProcessExit
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

CONTROLLERS = {   # controller argument: (controller in ros2_controllers.yaml, joint interface)
    'position': ('position_trajectory_controller', 'position'),
    'effort': ('effort_trajectory_controller', 'effort'),
    'forward_effort': ('forward_effort_controller', 'effort'),
    'velocity': ('forward_velocity_controller', 'velocity'),
}


def robot_description(share: str) -> str:
    """The shipped URDF with its ros2_control block: one arm, never two that disagree."""
    with open(os.path.join(share, 'urdf', 'two_link_arm.urdf')) as urdf:
        arm = urdf.read()
    with open(os.path.join(share, 'urdf', 'two_link_arm.ros2_control.xml')) as block:
        control = block.read()
    return arm.replace('</robot>', control + '</robot>')


def has_servo(scene: str) -> bool:
    """Whether the scene drives its joints through servos (servo.interface is its key)."""
    from arm_sim_ros.physics.scene import load_scene
    return load_scene(scene).servo is not None


def controlled(context):
    """The node, its joints starting on the interface of the controller the `controller`
    argument picks; that controller activated (the others loaded inactive) once the hardware
    has read the node's first JointState."""
    choice = LaunchConfiguration('controller').perform(context)
    if choice not in CONTROLLERS:
        raise ValueError(f"controller:={choice} is not one of {', '.join(CONTROLLERS)}")
    controller, interface = CONTROLLERS[choice]
    servo = ({'servo.interface': [interface, interface]}
             if has_servo(LaunchConfiguration('scene').perform(context)) else {})
    arm_sim = Node(
        package='arm_sim_ros', executable='arm_sim_node', name='arm_sim', output='screen',
        arguments=['--transport', LaunchConfiguration('transport').perform(context)],
        parameters=[{'scene': ParameterValue(LaunchConfiguration('scene'), value_type=str),
                     'policy': ParameterValue(LaunchConfiguration('policy'), value_type=str),
                     'lockstep': ParameterValue(LaunchConfiguration('lockstep'), value_type=bool),
                     'publish_clock': True} | servo],   # default topics
    )
    waiter = Node(package='arm_sim_ros', executable='arm_sim_controllers', output='screen',
                  arguments=['wait'])
    others = [name for name, _ in CONTROLLERS.values() if name != controller]
    spawners = [Node(package='controller_manager', executable='spawner', output='screen',
                     arguments=[controller]),
                Node(package='controller_manager', executable='spawner', output='screen',
                     arguments=[*sorted(set(others)), '--inactive'])]

    def started(event, _context):
        return spawners if event.returncode == 0 else [LogInfo(
            msg='arm_sim_controllers wait failed: the controllers are not started')]

    return [arm_sim, waiter, RegisterEventHandler(OnProcessExit(target_action=waiter,
                                                                on_exit=started))]


def generate_launch_description():
    share = get_package_share_directory('arm_sim_ros')
    use_sim_time = ParameterValue(LaunchConfiguration('use_sim_time'), value_type=bool)
    arguments = [
        DeclareLaunchArgument('scene', default_value='servo_hold',
                              description='preset scene; servo_hold starts the arm held'),
        DeclareLaunchArgument('policy', default_value='command_gravity_compensation',
                              description='command, or command_gravity_compensation to feed '
                                          'gravity forward'),
        DeclareLaunchArgument('controller', default_value='position',
                              description='the controller active at start: position, effort '
                                          '(trajectory controllers), forward_effort or '
                                          'velocity (forward controllers)'),
        DeclareLaunchArgument('use_sim_time', default_value='false',
                              description='controller_manager and robot_state_publisher on '
                                          "the node's /clock"),
        DeclareLaunchArgument('lockstep', default_value='false',
                              description='the node advances one tick per command'),
        DeclareLaunchArgument('rviz', default_value='false',
                              description='start rviz2 with rviz/arm_sim.rviz'),
        DeclareLaunchArgument('transport', default_value='auto',
                              description="the node's: rclpy (auto, where ROS is sourced) or "
                                          'dds (its own Cyclone DDS; parameters need '
                                          'RMW_IMPLEMENTATION=rmw_cyclonedds_cpp)'),
    ]
    # controller_manager reads the URDF from robot_state_publisher's /robot_description topic
    control = Node(
        package='controller_manager', executable='ros2_control_node', output='screen',
        parameters=[os.path.join(share, 'config', 'ros2_controllers.yaml'),
                    {'use_sim_time': use_sim_time}],
    )
    broadcaster = Node(
        package='controller_manager', executable='spawner', output='screen',
        arguments=['joint_state_broadcaster', '--controller-ros-args',
                   '-r /joint_states:=/broadcaster/joint_states'],
    )
    # every controller switch sets the node's servo.interface to what the active ones claim
    follower = Node(package='arm_sim_ros', executable='arm_sim_controllers', output='screen',
                    arguments=['follow'])
    state_publisher = Node(package='robot_state_publisher', executable='robot_state_publisher',
                           output='screen',
                           parameters=[{'robot_description': robot_description(share),
                                        'use_sim_time': use_sim_time}])
    rviz2 = Node(package='rviz2', executable='rviz2', output='screen',
                 arguments=['-d', os.path.join(share, 'rviz', 'arm_sim.rviz')],
                 condition=IfCondition(LaunchConfiguration('rviz')))
    return LaunchDescription(arguments + [OpaqueFunction(function=controlled), control,
                                          broadcaster, follower, state_publisher, rviz2])
