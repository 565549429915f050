"""The arm_sim node driven by ros2_control: controller_manager with the topic-based
hardware interface (urdf/two_link_arm.ros2_control.xml), a joint_state_broadcaster and the
controller the `controller` argument picks (config/ros2_controllers.yaml), plus
robot_state_publisher.

    ros2 launch arm_sim_ros arm_sim_ros2_control.launch.py                  # position JTC
    ros2 action send_goal /position_trajectory_controller/follow_joint_trajectory \
        control_msgs/action/FollowJointTrajectory "{trajectory: {joint_names: \
        [shoulder_joint, elbow_joint], points: [{positions: [0.8, -0.4], \
        time_from_start: {sec: 2}}]}}"
    ros2 launch arm_sim_ros arm_sim_ros2_control.launch.py controller:=effort
    ros2 launch arm_sim_ros arm_sim_ros2_control.launch.py controller:=forward_effort
    ros2 topic pub --once /forward_effort_controller/commands \
        std_msgs/msg/Float64MultiArray "{data: [5.0, 1.0]}"
    ros2 launch arm_sim_ros arm_sim_ros2_control.launch.py use_sim_time:=true lockstep:=true

The arm starts held: the default scene servo_hold holds its initial pose with joint servos
(position) or gravity feed-forward (effort: policy command_gravity_compensation), until a
controller commands it. The node follows each joint's command in the interface the
controller claims (servo.interface, set here from `controller` when the scene has servos).
Needs ros2_control, ros2_controllers (joint_trajectory_controller, forward_command_controller,
joint_state_broadcaster) and topic_based_hardware_interfaces.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

CONTROLLERS = {   # controller argument: (controller in ros2_controllers.yaml, joint interface)
    'position': ('position_trajectory_controller', 'position'),
    'effort': ('effort_trajectory_controller', 'effort'),
    'forward_effort': ('forward_effort_controller', 'effort'),
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
    """The node and the controller the `controller` argument picks, joint interfaces to match."""
    choice = LaunchConfiguration('controller').perform(context)
    if choice not in CONTROLLERS:
        raise ValueError(f"controller:={choice} is not one of {', '.join(CONTROLLERS)}")
    controller, interface = CONTROLLERS[choice]
    servo = ({'servo.interface': [interface, interface]}
             if has_servo(LaunchConfiguration('scene').perform(context)) else {})
    arm_sim = Node(
        package='arm_sim_ros', executable='arm_sim_node', name='arm_sim', output='screen',
        parameters=[{'scene': ParameterValue(LaunchConfiguration('scene'), value_type=str),
                     'policy': ParameterValue(LaunchConfiguration('policy'), value_type=str),
                     'lockstep': ParameterValue(LaunchConfiguration('lockstep'), value_type=bool),
                     # under use_sim_time controller_manager waits for /clock to move before
                     # its first command (and after lockstep is switched on): a lockstep
                     # node then ticks on its own each 0.1 s without one
                     'lockstep_wait': 0.1,
                     'publish_clock': True} | servo],   # default topics
    )
    spawner = Node(package='controller_manager', executable='spawner', output='screen',
                   arguments=[controller])
    return [arm_sim, spawner]


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
                              description='position, effort (trajectory controllers) or '
                                          'forward_effort'),
        DeclareLaunchArgument('use_sim_time', default_value='false',
                              description='controller_manager and robot_state_publisher on '
                                          "the node's /clock"),
        DeclareLaunchArgument('lockstep', default_value='false',
                              description='the node advances one tick per command'),
        DeclareLaunchArgument('rviz', default_value='false',
                              description='start rviz2 with rviz/arm_sim.rviz'),
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
    state_publisher = Node(package='robot_state_publisher', executable='robot_state_publisher',
                           output='screen',
                           parameters=[{'robot_description': robot_description(share),
                                        'use_sim_time': use_sim_time}])
    rviz2 = Node(package='rviz2', executable='rviz2', output='screen',
                 arguments=['-d', os.path.join(share, 'rviz', 'arm_sim.rviz')],
                 condition=IfCondition(LaunchConfiguration('rviz')))
    return LaunchDescription(arguments + [OpaqueFunction(function=controlled), control,
                                          broadcaster, state_publisher, rviz2])
