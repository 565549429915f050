"""The node's command callbacks: torque, JointState and set-point commands handed to the
intake (commands.py), then applied to the simulator by the core (core.py) they are part of;
in lockstep, each answers the latest state (schedule.Lockstep) and so lets the next tick
happen."""
from __future__ import annotations

from ...physics.effects import servo


class CommandInput:
    """ArmSimCore's command callbacks; the transports call them as messages arrive."""

    def on_command(self, data) -> str | None:
        """Take [tau1, tau2] from joint_torque_commands; returns the refusal reason, if any."""
        return self._apply(*self.commands.take(data, self.config.scene.policy,
                                               self.config.values["torque_limit"], self.sim.time))

    def on_joint_state_command(self, names, position, velocity, effort,
                               stamp_ns: int | None = None) -> str | None:
        """Take a sensor_msgs/JointState command from joint_commands (values by joint name,
        each joint taking what its servo.interface takes); returns the refusal reason, if any.
        `stamp_ns`, its header's: in lockstep, the state it answers (schedule.Lockstep)."""
        if self.config.values["lockstep"] and not self.lockstep.answers(
                stamp_ns, self.start_stamp_ns):
            self._stale(stamp_ns)
            return None
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
        if self.config.values["lockstep"]:
            # The latest state is answered: by an all-NaN command too (ros2_control's
            # hardware sends those while no controller claims the joints, and
            # controller_manager's cycles wait on the tick), and by a refused one, the loop
            # going on under the last good command.
            self.lockstep.answered = True
            self.lockstep_tick()
        return reason

    def lockstep_tick(self) -> None:
        """In lockstep, the tick the answer to the latest state lets happen, unless paused
        (a paused node holds the answer until it plays or is stepped)."""
        if self.lockstep.answered and not self.paused:
            self.lockstep.queue(self._tick())

    def _stale(self, stamp_ns: int) -> None:
        self.lockstep.stale += 1
        self.warnings.warning("stale", f"a command answered the state at {stamp_ns} ns, "
                              f"which was answered already (the latest is at "
                              f"{self.lockstep.published} ns): ignored, as lockstep ticks "
                              "once per state")
