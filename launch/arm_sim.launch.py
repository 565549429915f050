"""The arm_sim node with robot_state_publisher, and RViz to watch the arm move.

    ros2 launch arm_sim_ros arm_sim.launch.py
    ros2 launch arm_sim_ros arm_sim.launch.py rviz:=true
    ros2 launch arm_sim_ros arm_sim.launch.py scene:=damped_release publish_rate:=50.0
    ros2 launch arm_sim_ros arm_sim.launch.py params_file:=/path/to/my_arm_sim.yaml

The node reads its parameters from `params_file` (default: the installed
config/arm_sim.yaml); the `scene` and `publish_rate` arguments are applied after it, so
they win. robot_state_publisher publishes urdf/two_link_arm.urdf on /robot_description and
turns /joint_states into TF; with rviz:=true, rviz2 shows it with rviz/arm_sim.rviz: z up,
the arm upright in its vertical plane, seen from the side where positive angles turn
counter-clockwise.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def generate_launch_description():
    share = get_package_share_directory('arm_sim_ros')
    with open(os.path.join(share, 'urdf', 'two_link_arm.urdf')) as urdf:
        robot_description = urdf.read()

    scene = DeclareLaunchArgument(
        'scene', default_value='release',
        description='preset scene (arm-sim scenes lists them)')
    publish_rate = DeclareLaunchArgument(
        'publish_rate', default_value='100.0',
        description='joint_states per simulated second; must divide into step_size steps')
    params_file = DeclareLaunchArgument(
        'params_file', default_value=os.path.join(share, 'config', 'arm_sim.yaml'),
        description='ROS 2 parameters file for the arm_sim node')
    rviz = DeclareLaunchArgument(
        'rviz', default_value='false', description='start rviz2 with rviz/arm_sim.rviz')

    arm_sim = Node(
        package='arm_sim_ros',
        executable='arm_sim_node',
        name='arm_sim',
        output='screen',
        parameters=[
            LaunchConfiguration('params_file'),
            {
                # Typed, so `scene:=1` stays text and `publish_rate:=50` arrives as a double.
                'scene': ParameterValue(LaunchConfiguration('scene'), value_type=str),
                'publish_rate': ParameterValue(LaunchConfiguration('publish_rate'),
                                               value_type=float),
            },
        ],
    )
    robot_state_publisher = Node(
        package='robot_state_publisher',
        executable='robot_state_publisher',
        output='screen',
        parameters=[{'robot_description': robot_description}],
    )
    rviz2 = Node(
        package='rviz2',
        executable='rviz2',
        output='screen',
        arguments=['-d', os.path.join(share, 'rviz', 'arm_sim.rviz')],
        condition=IfCondition(LaunchConfiguration('rviz')),
    )

    return LaunchDescription([scene, publish_rate, params_file, rviz, arm_sim,
                              robot_state_publisher, rviz2])
