"""The ROS 2 Simulation Interfaces on rclpy: served when the `simulation_interfaces` package
imports (ros-jazzy-simulation-interfaces), else one line says so. The same services, action
and names as on dds (dds_simulation.py, dds_action.py), over the same SimulationControl
(simulation.py) and the same rules for SimulateSteps goals (simulate_steps.py); rclpy's
ActionServer keeps the goals."""
from __future__ import annotations

import time

from ..services.simulate_steps import canceled, interrupted, refusal, waiting
from ..services.simulation import RESULT_OK, RESULT_OPERATION_FAILED


def serve(node, control) -> list:
    """Create the services and the action on `node` (under its namespace); [] without the
    package."""
    try:
        from rclpy.action import ActionServer, CancelResponse
        from simulation_interfaces import srv
        from simulation_interfaces.action import SimulateSteps
        from simulation_interfaces.msg import Result, SimulationState, SimulatorFeatures
    except ImportError:
        node.get_logger().info("simulation_interfaces is not installed: the Simulation "
                               "Interfaces are not served (~/reset is)")
        return []

    def features(request, response):
        listed, info = control.features()
        response.features = SimulatorFeatures(features=list(listed), custom_info=info)
        return response

    def get_state(request, response):
        response.state = SimulationState(state=control.state)
        response.result = Result(result=Result.RESULT_OK)
        return response

    def answer(call):
        def handler(request, response):
            code, message = call(request)
            response.result = Result(result=code, error_message=message)
            return response
        return handler

    async def step(request, response):
        """A tick per turn of the executor, which answers other requests between two."""
        answered = []
        now = control.call_steps(request.steps, lambda *result: answered.append(result))
        while now is None and not answered:
            control.advance()
            await Turn()
        code, message = now or answered[0]
        response.result = Result(result=code, error_message=message)
        return response

    running = []      # the SimulateSteps goal executing (executor)
    control.goal_running = lambda: bool(running)

    return [
        node.create_service(srv.GetSimulatorFeatures, "get_simulator_features", features),
        node.create_service(srv.GetSimulationState, "get_simulation_state", get_state),
        node.create_service(srv.SetSimulationState, "set_simulation_state",
                            answer(lambda request: control.set_state(request.state.state))),
        node.create_service(srv.StepSimulation, "step_simulation", step),
        node.create_service(srv.ResetSimulation, "reset_simulation",
                            answer(lambda request: control.reset(request.scope))),
        ActionServer(node, SimulateSteps, "simulate_steps",
                     execute_callback=executor(control, SimulateSteps, Result, lambda: (
                         node.count_subscribers("simulate_steps/_action/feedback") > 0),
                                               running),
                     cancel_callback=lambda goal_handle: CancelResponse.ACCEPT),
    ]


class Turn:
    """Awaited in a coroutine rclpy's executor runs: it takes other callbacks (a cancel)
    before the coroutine goes on."""

    def __await__(self):
        yield


def executor(control, action, result_type, listening, running=None):
    """SimulateSteps' execute callback: a tick, its feedback, a turn of the executor; a goal
    that cannot run (simulate_steps.refusal) is aborted saying why. `listening()`: the
    feedback has a reader (the first tick waits a moment for one); `running`: the goal
    executing, kept there."""
    running = [] if running is None else running

    async def execute(goal_handle):
        steps, done = goal_handle.request.steps, 0
        code, message = refusal(control, steps, bool(running)) or (RESULT_OK, "")
        if code == RESULT_OK:
            running.append(goal_handle)
            try:
                accepted = time.monotonic_ns()
                while waiting(accepted, time.monotonic_ns(), listening()) and \
                        not goal_handle.is_cancel_requested:
                    await Turn()
                epoch = control.epoch
                while done < steps and not goal_handle.is_cancel_requested:
                    if control.epoch == epoch and not control.ready():
                        await Turn()            # lockstep: the tick waits for its answer
                        continue
                    code, why = (RESULT_OPERATION_FAILED, control.why) if (
                        control.epoch != epoch) else control.step(1)
                    if code != RESULT_OK:           # set playing or stopped meanwhile
                        message = interrupted(done, steps, why)
                        break
                    done += 1
                    goal_handle.publish_feedback(action.Feedback(completed_steps=done,
                                                                 remaining_steps=steps - done))
                    await Turn()
            finally:
                running.remove(goal_handle)
        if code != RESULT_OK:
            goal_handle.abort()
        elif done < steps:
            goal_handle.canceled()
            message = canceled(done, steps)
        else:
            goal_handle.succeed()
        return action.Result(result=result_type(result=code, error_message=message))

    return execute
