"""The node's command callbacks: torque, JointState and set-point commands handed to the
intake (commands.py), then applied to the simulator by the core (core.py) they are part of."""
from __future__ import annotations

from ...physics.effects import servo


class CommandInput:
    """ArmSimCore's command callbacks; the transports call them as messages arrive."""

    def on_command(self, data) -> str | None:
        """Take [tau1, tau2] from joint_torque_commands; returns the refusal reason, if any."""
        return self._apply(*self.commands.take(data, self.config.scene.policy,
                                               self.config.values["torque_limit"], self.sim.time))

    def on_joint_state_command(self, names, position, velocity, effort) -> str | None:
        """Take a sensor_msgs/JointState command from joint_commands (values by joint name,
        each joint taking what its servo.interface takes); returns the refusal reason, if any."""
        v, interfaces = self.config.values, servo.interfaces(self.sim.dynamics)
        return self._apply(*self.commands.take_joint_state(
            names, (position, velocity, effort), v["joint_names"], interfaces,
            self.config.scene.policy, v["torque_limit"], self.sim.time))

    def on_setpoint_command(self, field: str, data) -> str | None:
        """Take [joint 1, joint 2] from position_commands or velocity_commands (`field`)."""
        return self._apply(*self.commands.take_array(field, data, servo.interfaces(
            self.sim.dynamics), self.config.scene.policy, self.sim.time))

    def _apply(self, reason: str | None, command, setpoints=None) -> str | None:
        if reason is not None:
            self.recorder.refused(reason)
        elif command is not None or setpoints:
            self._set_command(*self.commands.value, setpoints)
        if reason is None and self.config.values["lockstep"] and not self.paused:
            # a tick per command, an all-NaN one too (ros2_control's hardware sends those
            # while no controller claims the joints: controller_manager's cycles wait on it)
            self.lockstep_states.append(self._tick())
        return reason
