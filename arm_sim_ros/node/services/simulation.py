"""The ROS 2 Simulation Interfaces (simulation_interfaces, Jazzy) over the node core: the
simulation state (playing, paused, stopped), stepping exactly N ticks while paused, reset,
and the features list. Transports (dds_simulation.py, rclpy) turn requests into these calls
and the results into replies; the codes and states are the package's constants. The
SimulateSteps action's goals: simulate_steps.py.

One simulation step here is one tick of the node: steps_per_tick integration steps and one
JointState (and /clock) published. Paused: no physics, /clock holds, the held JointState
still goes out at the publish rate. Stopped is reset and paused (SimulationState.msg).
Resetting keeps stamps increasing (a clock that jumps back breaks use_sim_time nodes), so
the SCOPE_TIME reset is not offered.
"""
from __future__ import annotations

# simulation_interfaces/msg/Result
RESULT_FEATURE_UNSUPPORTED, RESULT_OK, RESULT_NOT_FOUND = 0, 1, 2
RESULT_INCORRECT_STATE, RESULT_OPERATION_FAILED = 3, 4
# simulation_interfaces/srv/SetSimulationState_Response
ALREADY_IN_TARGET_STATE, STATE_TRANSITION_ERROR, INCORRECT_TRANSITION = 101, 102, 103
# simulation_interfaces/msg/SimulationState
STATE_STOPPED, STATE_PLAYING, STATE_PAUSED, STATE_QUITTING = 0, 1, 2, 3
STATE_NAMES = {STATE_STOPPED: "stopped", STATE_PLAYING: "playing", STATE_PAUSED: "paused"}
# simulation_interfaces/srv/ResetSimulation_Request scopes
SCOPE_DEFAULT, SCOPE_TIME, SCOPE_STATE, SCOPE_SPAWNED, SCOPE_ALL = 0, 1, 2, 4, 255
# simulation_interfaces/msg/SimulatorFeatures: exactly what is served
SIMULATION_RESET, SIMULATION_RESET_STATE = 20, 22
SIMULATION_STATE_GETTING, SIMULATION_STATE_SETTING, SIMULATION_STATE_PAUSE = 24, 25, 26
STEP_SIMULATION_SINGLE, STEP_SIMULATION_MULTIPLE, STEP_SIMULATION_ACTION = 31, 32, 33
FEATURES = (SIMULATION_RESET, SIMULATION_RESET_STATE, SIMULATION_STATE_GETTING,
            SIMULATION_STATE_SETTING, SIMULATION_STATE_PAUSE, STEP_SIMULATION_SINGLE,
            STEP_SIMULATION_MULTIPLE, STEP_SIMULATION_ACTION)
CUSTOM_INFO = ("arm_sim: a planar two-link arm. One simulation step is one node tick "
               "(steps_per_tick integration steps, one JointState). Reset restores the "
               "scene's initial state; stamps and /clock keep increasing.")
MAX_STEPS = 1_000_000      # one StepSimulation call: beyond, the node would not answer for minutes
SERVICES = ("get_simulator_features", "get_simulation_state", "set_simulation_state",
            "step_simulation", "reset_simulation")


class SimulationControl:
    """Play, pause, stop, step and reset a node core, as the Simulation Interfaces ask."""

    def __init__(self, core, publish, take_commands=None):
        """`publish(JointStateData)`: the transport's JointState and /clock publisher;
        `take_commands()`: hands the commands waiting to the core, so that a command sent
        (and acknowledged) before a step request acts in the steps: deterministic."""
        self.core, self.publish, self.take_commands = core, publish, take_commands
        self.state = STATE_PLAYING

    def features(self) -> tuple:
        return FEATURES, CUSTOM_INFO

    def set_state(self, target: int) -> tuple[int, str]:
        """(result code, message) of a SetSimulationState request."""
        if target == self.state:
            return ALREADY_IN_TARGET_STATE, f"already {STATE_NAMES[target]}"
        if target == STATE_QUITTING:
            return RESULT_FEATURE_UNSUPPORTED, "quitting is not offered: stop the node itself"
        if target not in STATE_NAMES:
            return INCORRECT_TRANSITION, f"state {target} cannot be set here"
        if target == STATE_STOPPED:
            self.core.reset()
        self.state, self.core.paused = target, target != STATE_PLAYING
        self.core.log.info(f"simulation {STATE_NAMES[target]} at t = {self.core.sim.time:.6f} s")
        return RESULT_OK, ""

    def step(self, steps: int) -> tuple[int, str]:
        """Exactly `steps` ticks, each published, while paused (or stopped: then paused)."""
        if self.state == STATE_PLAYING:
            return RESULT_OPERATION_FAILED, "step_simulation needs the simulation paused"
        if steps > MAX_STEPS:
            return RESULT_OPERATION_FAILED, f"{steps} steps is beyond {MAX_STEPS} in one call"
        self.state = STATE_PAUSED
        if self.take_commands is not None:
            self.take_commands()
        for data in self.core.step_ticks(steps):
            self.publish(data)
        return RESULT_OK, ""

    def reset(self, scope: int) -> tuple[int, str]:
        """Back to the scene's initial state; playing, paused or stopped as before."""
        if scope not in (SCOPE_DEFAULT, SCOPE_ALL) and not scope & SCOPE_STATE:
            return RESULT_FEATURE_UNSUPPORTED, (f"reset scope {scope}: only the state is reset "
                                                "(stamps keep increasing, nothing is spawned)")
        self.core.reset()
        return RESULT_OK, ""
