"""The arm_sim node driven by ros2_control: controller_manager with the topic-based
hardware interface (urdf/two_link_arm.ros2_control.xml), a joint_state_broadcaster and an
effort controller, plus robot_state_publisher.

    ros2 launch arm_sim_ros arm_sim_ros2_control.launch.py
    ros2 topic pub --once /effort_controller/commands std_msgs/msg/Float64MultiArray \
        "{data: [20.0, 5.0]}"
    ros2 launch arm_sim_ros arm_sim_ros2_control.launch.py rviz:=true   # and rviz2

Needs ros2_control, ros2_controllers (forward_command_controller, joint_state_broadcaster)
and topic_based_hardware_interfaces. The node takes the controller's JointState efforts on
joint_commands and publishes joint_states, which the hardware interface reads.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def robot_description(share: str) -> str:
    """The shipped URDF with its ros2_control block: one arm, never two that disagree."""
    with open(os.path.join(share, 'urdf', 'two_link_arm.urdf')) as urdf:
        arm = urdf.read()
    with open(os.path.join(share, 'urdf', 'two_link_arm.ros2_control.xml')) as block:
        control = block.read()
    return arm.replace('</robot>', control + '</robot>')


def generate_launch_description():
    share = get_package_share_directory('arm_sim_ros')
    description = {'robot_description': robot_description(share)}
    scene = DeclareLaunchArgument('scene', default_value='gravity_compensation_at_rest',
                                  description='preset scene; its policy is served as command')
    arm_sim = Node(
        package='arm_sim_ros', executable='arm_sim_node', name='arm_sim', output='screen',
        parameters=[{'scene': ParameterValue(LaunchConfiguration('scene'), value_type=str),
                     'policy': 'command', 'command_timeout': 0.0}],   # default topics
    )
    control = Node(
        package='controller_manager', executable='ros2_control_node', output='screen',
        parameters=[description,
                    os.path.join(share, 'config', 'ros2_controllers.yaml')],
    )
    broadcaster = Node(
        package='controller_manager', executable='spawner', output='screen',
        arguments=['joint_state_broadcaster', '--controller-ros-args',
                   '-r /joint_states:=/broadcaster/joint_states'],
    )
    effort = Node(package='controller_manager', executable='spawner', output='screen',
                  arguments=['effort_controller'])
    state_publisher = Node(package='robot_state_publisher', executable='robot_state_publisher',
                           output='screen', parameters=[description])
    rviz = DeclareLaunchArgument('rviz', default_value='false',
                                 description='start rviz2 with rviz/arm_sim.rviz')
    rviz2 = Node(package='rviz2', executable='rviz2', output='screen',
                 arguments=['-d', os.path.join(share, 'rviz', 'arm_sim.rviz')],
                 condition=IfCondition(LaunchConfiguration('rviz')))
    return LaunchDescription([scene, rviz, arm_sim, control, broadcaster, effort,
                              state_publisher, rviz2])
