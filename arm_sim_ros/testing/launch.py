"""The node's launch actions in lockstep, for a user's own launch_testing test (needs ROS 2
sourced: launch_ros):

    from arm_sim_ros.testing.launch import arm_sim_in_lockstep

    @pytest.mark.launch_test
    def generate_test_description():
        return LaunchDescription([*arm_sim_in_lockstep("release", {"policy": "command"}),
                                  my_controller, launch_testing.actions.ReadyToTest()])

The node starts paused, in lockstep, with no tick of its own (wire.lockstep_parameters):
the test then attaches to it (wire.WireArm.attach) and runs it once the controller is up, so
the loop is ordered by stamps from its first state, whatever launch started first.
"""
from __future__ import annotations

from .wire import lockstep_parameters


def arm_sim_in_lockstep(scene: str = "release", parameters: dict | None = None, *,
                        name: str = "arm_sim", output: str = "screen", **node_options) -> list:
    """[the arm_sim Node action] with lockstep_parameters(scene, parameters)."""
    from launch_ros.actions import Node
    return [Node(package="arm_sim_ros", executable="arm_sim_node", name=name, output=output,
                 parameters=[lockstep_parameters(scene, parameters)], **node_options)]
