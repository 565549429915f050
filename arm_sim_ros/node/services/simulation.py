"""The ROS 2 Simulation Interfaces (simulation_interfaces, Jazzy) over the node core: the
simulation state (playing, paused, stopped), stepping exactly N ticks while paused, reset,
and the features list. Transports (dds_simulation.py, rclpy) turn requests into these calls
and the results into replies; the codes and states are the package's constants. The
SimulateSteps action's goals: simulate_steps.py.

One simulation step here is one tick of the node: steps_per_tick integration steps and one
JointState (and /clock) published. Paused: no physics, /clock holds, the held JointState
still goes out at the publish rate (in lockstep: once, and a tick asked for waits for the
command that answers the latest state, as every lockstep tick does). Stopped is reset and paused (SimulationState.msg).
Resetting keeps stamps increasing (a clock that jumps back breaks use_sim_time nodes), so
the SCOPE_TIME reset is not offered (nor SCOPE_ALL, which holds it).

A StepSimulation call ticks one tick per `advance()`, as a SimulateSteps goal does, so that
the transport answers other requests between two ticks; its reply comes after its last
tick. Calls run one after another; playing or stopping interrupts them (and a goal).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

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
MAX_STEPS = 1_000_000      # ticks of one StepSimulation call or goal (~2.8 h at 100 Hz)
SERVICES = ("get_simulator_features", "get_simulation_state", "set_simulation_state",
            "step_simulation", "reset_simulation")


def interrupted(done: int, steps: int, why: str) -> str:
    return f"interrupted after {done} of {steps} steps: {why}"


@dataclass
class StepCall:
    """A StepSimulation call in progress: `done(code, message)` answers it."""

    steps: int
    done: object
    completed: int = 0


class SimulationControl:
    """Play, pause, stop, step and reset a node core, as the Simulation Interfaces ask."""

    def __init__(self, core, publish, take_commands=None):
        """`publish(JointStateData)`: the transport's JointState and /clock publisher;
        `take_commands()`: hands the commands waiting to the core, so that a command sent
        (and acknowledged) before a step request acts in the steps: deterministic."""
        self.core, self.publish, self.take_commands = core, publish, take_commands
        self.state = STATE_PAUSED if core.config.values["paused"] else STATE_PLAYING
        core.paused = self.state == STATE_PAUSED
        self.calls = deque()          # StepSimulation calls, the first ticking
        self.epoch, self.why = 0, ""  # raised by play and stop: stepping begun before ends
        self.goal_running = lambda: False   # the SimulateSteps server's (it attaches it)

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
        if target != STATE_PAUSED:    # a goal or call stepping stops here, its reply says so
            self.interrupt(f"set {STATE_NAMES[target]}")
        self.state, self.core.paused = target, target != STATE_PLAYING
        if target == STATE_PLAYING:
            self.core.lockstep_tick()       # in lockstep, an answer held while paused
        self.core.log.info(f"simulation {STATE_NAMES[target]} at t = {self.core.sim.time:.6f} s")
        return RESULT_OK, ""

    def step(self, steps: int) -> tuple[int, str]:
        """Exactly `steps` ticks now, each published, while paused (or stopped: then
        paused): a goal's tick. A StepSimulation call: call_steps."""
        if self.state == STATE_PLAYING:
            return RESULT_OPERATION_FAILED, "step_simulation needs the simulation paused"
        if steps > MAX_STEPS:
            return RESULT_OPERATION_FAILED, f"{steps} steps is beyond {MAX_STEPS} in one call"
        self.state = STATE_PAUSED
        if self.take_commands is not None:
            self.take_commands()
        for _ in range(steps):
            self.publish(self.core.step_tick())
        return RESULT_OK, ""

    def ready(self) -> bool:
        """A tick asked for may happen now: in lockstep, once the latest state is answered."""
        return not self.core.config.values["lockstep"] or self.core.lockstep.answered

    def call_steps(self, steps: int, done) -> tuple[int, str] | None:
        """A StepSimulation call: (code, message) at once where it cannot run (or asks for
        none), else None: its ticks come one per advance(), then `done(code, message)`."""
        if self.goal_running():
            return RESULT_OPERATION_FAILED, "a simulate_steps goal is running"
        if self.state == STATE_PLAYING or steps > MAX_STEPS or steps == 0:
            return self.step(steps)           # refused, or no tick to take: answered now
        self.state = STATE_PAUSED
        self.calls.append(StepCall(steps, done))
        return None

    def advance(self) -> bool:
        """One tick of the first StepSimulation call (its reply after its last); False when
        none is waiting."""
        if not self.calls:
            return False
        call = self.calls[0]
        if not call.completed and self.take_commands is not None:
            self.take_commands()     # sent before the call: they act in its steps
        if not self.ready():         # lockstep: each tick waits for its answer
            return False
        self.publish(self.core.step_tick())
        call.completed += 1
        if call.completed == call.steps:
            self.calls.popleft()
            call.done(RESULT_OK, "")
        return True

    def interrupt(self, why: str) -> None:
        """Stepping begun ends here: the calls are answered, a goal ends at its next turn."""
        self.epoch, self.why = self.epoch + 1, why
        calls, self.calls = self.calls, deque()
        for call in calls:
            call.done(RESULT_OPERATION_FAILED, interrupted(call.completed, call.steps, why))

    def reset(self, scope: int) -> tuple[int, str]:
        """Back to the scene's initial state; playing, paused or stopped as before. A scope
        that holds time (SCOPE_ALL too) is refused and changes nothing: time only goes on."""
        if scope & SCOPE_TIME or (scope != SCOPE_DEFAULT and not scope & SCOPE_STATE):
            return RESULT_FEATURE_UNSUPPORTED, (
                f"reset scope {scope}: only the state is reset (SCOPE_STATE or "
                "SCOPE_DEFAULT): stamps and /clock keep increasing (a clock that jumps back "
                "breaks use_sim_time nodes) and nothing is spawned; nothing was reset")
        self.core.reset()
        return RESULT_OK, ""
