"""The ROS 2 Simulation Interfaces on rclpy: served when the `simulation_interfaces` package
imports (ros-jazzy-simulation-interfaces), else one line says so. The same services and
names as on dds (dds_simulation.py), over the same SimulationControl (simulation.py)."""
from __future__ import annotations


def serve(node, control) -> list:
    """Create the services on `node` (under its namespace); [] without the package."""
    try:
        from simulation_interfaces import srv
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

    return [
        node.create_service(srv.GetSimulatorFeatures, "get_simulator_features", features),
        node.create_service(srv.GetSimulationState, "get_simulation_state", get_state),
        node.create_service(srv.SetSimulationState, "set_simulation_state",
                            answer(lambda request: control.set_state(request.state.state))),
        node.create_service(srv.StepSimulation, "step_simulation",
                            answer(lambda request: control.step(request.steps))),
        node.create_service(srv.ResetSimulation, "reset_simulation",
                            answer(lambda request: control.reset(request.scope))),
    ]
