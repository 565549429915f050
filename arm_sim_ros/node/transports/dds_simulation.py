"""The ROS 2 Simulation Interfaces (simulation_interfaces, Jazzy) on the dds transport, on
the wire as rmw_cyclonedds serves them: the same layout as the parameter services
(dds_services.py: `rq/<name>Request` / `rr/<name>Reply`, the request header, USER_DATA
with the RIHS01 type hash), the types as rosidl generates them from the package's .msg and
.srv files. Served under the node's namespace: get_simulator_features,
get_simulation_state, set_simulation_state, step_simulation, reset_simulation; the
SimulateSteps action: dds_action.py. (No `from __future__ import annotations`: cyclonedds
resolves field types at runtime.)
"""

from dataclasses import dataclass, field

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.annotations import final
from cyclonedds.idl.types import sequence, uint8, uint16, uint64

from ..services import simulation as sim
from ..wire.service_types import ros_type_names, service


@final
@dataclass
class Result(IdlStruct, typename="simulation_interfaces.msg.dds_.Result_"):
    result: uint8 = 0
    error_message: str = ""


@final
@dataclass
class SimulationState(IdlStruct, typename="simulation_interfaces.msg.dds_.SimulationState_"):
    state: uint8 = 0


@final
@dataclass
class SimulatorFeatures(IdlStruct, typename="simulation_interfaces.msg.dds_.SimulatorFeatures_"):
    features: sequence[uint16] = field(default_factory=list)
    spawn_formats: sequence[str] = field(default_factory=list)
    custom_info: str = ""


# --- the services (wire/service_types.py: rmw_cyclonedds' request header first) ------------

def _service(name: str, request: dict, response: dict, defaults=None) -> tuple:
    """(rosidl name, request type, response type) of a simulation_interfaces service."""
    return (name, *service(f"simulation_interfaces/srv/{name}", request, response, defaults))


TYPES = {   # service: (its rosidl name, request type, response type)
    "get_simulator_features": _service("GetSimulatorFeatures", {},
                                       {"features": SimulatorFeatures}),
    "get_simulation_state": _service("GetSimulationState", {},
                                     {"state": SimulationState, "result": Result}),
    "set_simulation_state": _service("SetSimulationState", {"state": SimulationState},
                                     {"result": Result}),
    "step_simulation": _service("StepSimulation", {"steps": uint64}, {"result": Result},
                                defaults={"steps": 1}),
    "reset_simulation": _service("ResetSimulation", {"scope": uint8}, {"result": Result}),
}

# RIHS01 hashes (REP 2011) as rosidl computes them for Jazzy from the package's definitions;
# test_simulation_interfaces checks each against rosbags and rosidl-generated code.
TYPE_HASHES = {
    "simulation_interfaces/srv/GetSimulatorFeatures_Request":
        "RIHS01_982b8c1adef1d556f6ecdc019d1269fc39413626a9222d73b4fc874bd798b7db",
    "simulation_interfaces/srv/GetSimulatorFeatures_Response":
        "RIHS01_ede4dc8227cbb2f86a24612c999dcaa67d17dab21dab566cefdc233e7a2a65d1",
    "simulation_interfaces/srv/GetSimulationState_Request":
        "RIHS01_c6d65bc5c0a95ca2886bc57f146f803e01722c84ddb5acd5f32a4417f55eecfb",
    "simulation_interfaces/srv/GetSimulationState_Response":
        "RIHS01_dc80ce852a5ab04c2b23cdd47910cee1bcc46e0f1931cac85825e6916b15517f",
    "simulation_interfaces/srv/SetSimulationState_Request":
        "RIHS01_73283477d36ba619db2ac37a3e599077ca244502c9d8ca2a7183afcb2224f476",
    "simulation_interfaces/srv/SetSimulationState_Response":
        "RIHS01_6351aebf2bbf06e2993977918b944240f7403b532a9e4a344c53e71a56afd174",
    "simulation_interfaces/srv/StepSimulation_Request":
        "RIHS01_cda33f6887815f3dce0f90e61fd8efd39bda13ae264ddede15c33fbad890630e",
    "simulation_interfaces/srv/StepSimulation_Response":
        "RIHS01_5b4acf2d0ce7c3fc125d0bef2acb9b5a81377e80db6b696b81beeffb9824fb5c",
    "simulation_interfaces/srv/ResetSimulation_Request":
        "RIHS01_2c766d09c3aa30f01fadc55a42fd760b63db358c7d1d3b6a64ea9978225ffbc7",
    "simulation_interfaces/srv/ResetSimulation_Response":
        "RIHS01_718428121e0f1755720878d3c28f1688da7581ee5a5d56d26d10d941a28a50a0",
}
ROS_TYPE_NAMES = ros_type_names(*(kinds for _, *kinds in TYPES.values()))


class DdsSimulation:
    """Request -> reply fields for each service, over a SimulationControl (attach it, and
    `reply_later(service, reply, request)`); `advance()` between polls: one tick of a
    step_simulation call, answered after its last."""

    def __init__(self):
        self.control = self.reply_later = None

    def advance(self) -> bool:
        return self.control is not None and self.control.advance()

    @property
    def busy(self) -> bool:
        return self.control is not None and bool(self.control.calls)

    def services(self) -> list:
        """(service, request type, response type, handler) for DdsServices."""
        handlers = {"get_simulator_features": self._features, "get_simulation_state": self._get,
                    "set_simulation_state": self._set, "step_simulation": self._step,
                    "reset_simulation": self._reset}
        return [(service, request, response, handlers[service])
                for service, (_, request, response) in TYPES.items()]

    def _features(self, request) -> dict:
        features, info = self.control.features()
        return {"features": SimulatorFeatures(features=list(features), custom_info=info)}

    def _get(self, request) -> dict:
        return {"state": SimulationState(self.control.state), "result": Result(sim.RESULT_OK)}

    def _set(self, request) -> dict:
        return {"result": Result(*self.control.set_state(request.state.state))}

    def _step(self, request) -> dict | None:
        def done(code, message):
            response = TYPES["step_simulation"][2]
            self.reply_later("step_simulation", response(
                guid=request.guid, seq=request.seq, result=Result(code, message)), request)
        now = self.control.call_steps(request.steps, done)
        return None if now is None else {"result": Result(*now)}

    def _reset(self, request) -> dict:
        return {"result": Result(*self.control.reset(request.scope))}
