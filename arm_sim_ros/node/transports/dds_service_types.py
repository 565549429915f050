"""rcl_interfaces parameter messages and services, and std_srvs/Trigger, as cyclonedds IDL
types laid out exactly as rmw_cyclonedds (Jazzy) puts them on the wire: the messages as
final keyless structs (XCDR1), the services with rmw_cyclonedds' request header first
(wire/service_types.py). (No `from __future__ import annotations`: cyclonedds resolves field
types at runtime.)
"""

from dataclasses import dataclass, field

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.annotations import final
from cyclonedds.idl.types import float64, int64, sequence, uint8, uint64

from ..wire.messages import Time
from ..wire.service_types import ros_type_names, service


# --- rcl_interfaces/msg --------------------------------------------------------------------

@final
@dataclass
class ParameterValue(IdlStruct, typename="rcl_interfaces.msg.dds_.ParameterValue_"):
    type: uint8 = 0
    bool_value: bool = False
    integer_value: int64 = 0
    double_value: float64 = 0.0
    string_value: str = ""
    byte_array_value: sequence[uint8] = field(default_factory=list)
    bool_array_value: sequence[bool] = field(default_factory=list)
    integer_array_value: sequence[int64] = field(default_factory=list)
    double_array_value: sequence[float64] = field(default_factory=list)
    string_array_value: sequence[str] = field(default_factory=list)


@final
@dataclass
class Parameter(IdlStruct, typename="rcl_interfaces.msg.dds_.Parameter_"):
    name: str = ""
    value: ParameterValue = field(default_factory=ParameterValue)


@final
@dataclass
class SetParametersResult(IdlStruct, typename="rcl_interfaces.msg.dds_.SetParametersResult_"):
    successful: bool = False
    reason: str = ""


@final
@dataclass
class FloatingPointRange(IdlStruct, typename="rcl_interfaces.msg.dds_.FloatingPointRange_"):
    from_value: float64 = 0.0
    to_value: float64 = 0.0
    step: float64 = 0.0


@final
@dataclass
class IntegerRange(IdlStruct, typename="rcl_interfaces.msg.dds_.IntegerRange_"):
    from_value: int64 = 0
    to_value: int64 = 0
    step: uint64 = 0


@final
@dataclass
class ParameterDescriptor(IdlStruct, typename="rcl_interfaces.msg.dds_.ParameterDescriptor_"):
    name: str = ""
    type: uint8 = 0
    description: str = ""
    additional_constraints: str = ""
    read_only: bool = False
    dynamic_typing: bool = False
    floating_point_range: sequence[FloatingPointRange, 1] = field(default_factory=list)
    integer_range: sequence[IntegerRange, 1] = field(default_factory=list)


@final
@dataclass
class ListParametersResult(IdlStruct, typename="rcl_interfaces.msg.dds_.ListParametersResult_"):
    names: sequence[str] = field(default_factory=list)
    prefixes: sequence[str] = field(default_factory=list)


@final
@dataclass
class ParameterEvent(IdlStruct, typename="rcl_interfaces.msg.dds_.ParameterEvent_"):
    stamp: Time = field(default_factory=Time)
    node: str = ""
    new_parameters: sequence[Parameter] = field(default_factory=list)
    changed_parameters: sequence[Parameter] = field(default_factory=list)
    deleted_parameters: sequence[Parameter] = field(default_factory=list)


# --- rcl_interfaces/srv and std_srvs/srv/Trigger (wire/service_types.py: the header first) ---

ListParametersRequest, ListParametersResponse = service(
    "rcl_interfaces/srv/ListParameters",
    {"prefixes": sequence[str], "depth": uint64}, {"result": ListParametersResult})
GetParametersRequest, GetParametersResponse = service(
    "rcl_interfaces/srv/GetParameters",
    {"names": sequence[str]}, {"values": sequence[ParameterValue]})
SetParametersRequest, SetParametersResponse = service(
    "rcl_interfaces/srv/SetParameters",
    {"parameters": sequence[Parameter]}, {"results": sequence[SetParametersResult]})
SetParametersAtomicallyRequest, SetParametersAtomicallyResponse = service(
    "rcl_interfaces/srv/SetParametersAtomically",
    {"parameters": sequence[Parameter]}, {"result": SetParametersResult})
DescribeParametersRequest, DescribeParametersResponse = service(
    "rcl_interfaces/srv/DescribeParameters",
    {"names": sequence[str]}, {"descriptors": sequence[ParameterDescriptor]})
GetParameterTypesRequest, GetParameterTypesResponse = service(
    "rcl_interfaces/srv/GetParameterTypes", {"names": sequence[str]}, {"types": sequence[uint8]})
TriggerRequest, TriggerResponse = service(
    "std_srvs/srv/Trigger", {}, {"success": bool, "message": str})

# ROS interface name of each wire type: its RIHS01 hash goes into the endpoints' USER_DATA.
ROS_TYPE_NAMES = {ParameterEvent: "rcl_interfaces/msg/ParameterEvent"} | ros_type_names(
    (ListParametersRequest, ListParametersResponse), (GetParametersRequest, GetParametersResponse),
    (SetParametersRequest, SetParametersResponse),
    (SetParametersAtomicallyRequest, SetParametersAtomicallyResponse),
    (DescribeParametersRequest, DescribeParametersResponse),
    (GetParameterTypesRequest, GetParameterTypesResponse), (TriggerRequest, TriggerResponse))

# RIHS01 hashes (REP 2011) of the request/response messages as rosidl computes them for Jazzy;
# test_dds_services checks each against the rosbags library.
TYPE_HASHES = {
    "rcl_interfaces/msg/ParameterEvent":
        "RIHS01_043e627780fcad87a22d225bc2a037361dba713fca6a6b9f4b869a5aa0393204",
    "rcl_interfaces/srv/ListParameters_Request":
        "RIHS01_a1b0b5d6b967a5b8ac5bc8563c3ea678f349e312a6a4967227c5a96bc5ce38df",
    "rcl_interfaces/srv/ListParameters_Response":
        "RIHS01_31b937b82de3612426be79f231e386259f97e8dc843e3f2845288b4bfa296bdd",
    "rcl_interfaces/srv/GetParameters_Request":
        "RIHS01_135a9e1c3d7cebef792f6687d7ddf99949b21a0bd9a320d863a9110a3f5cf4d6",
    "rcl_interfaces/srv/GetParameters_Response":
        "RIHS01_9fa773b46e39cc5d02db6224d8fd520bb9caeeffc2b27c96c1e59431baba9f2a",
    "rcl_interfaces/srv/SetParameters_Request":
        "RIHS01_130d46386b7e84ea9ecf60608a4d83cbe5e5cb7c6cc5b712b7a4e3a6c254e932",
    "rcl_interfaces/srv/SetParameters_Response":
        "RIHS01_7a0e8140a0b8d98308fa81a5403a766e610af29a239caf54b7553227906fc266",
    "rcl_interfaces/srv/SetParametersAtomically_Request":
        "RIHS01_db0bd950ed5ed867a0e90b225e44dea382d762c0762ff3e0ee842190042a59e5",
    "rcl_interfaces/srv/SetParametersAtomically_Response":
        "RIHS01_31b1a38c5b0b9d893ee24da45f69638f4561c78461d82d52750f429b534502b8",
    "rcl_interfaces/srv/DescribeParameters_Request":
        "RIHS01_05dd1c2bc87dec2627105c8070d6f9725c781a4f2ab852975bf105462b82b644",
    "rcl_interfaces/srv/DescribeParameters_Response":
        "RIHS01_ad6747319613c6131589e062e095b469a46cc764f7d0f12a001a49e6cd893995",
    "rcl_interfaces/srv/GetParameterTypes_Request":
        "RIHS01_87d7ec5ef545d4daa289d500025d31fb2437bc8b8365ca367161c4dac4be33fd",
    "rcl_interfaces/srv/GetParameterTypes_Response":
        "RIHS01_ac1335dce67c478e669434f6ac2fbff34fcd529580f272d3006785ba8b54e47f",
    "std_srvs/srv/Trigger_Request":
        "RIHS01_d010825374ce8918e72bfd826c82603e60f45419e932ea976f807b74a863a199",
    "std_srvs/srv/Trigger_Response":
        "RIHS01_2d946c21e2fc3f1e9ca6986a8191d85fcc70097a8bb7771a053564bc47009cdf",
}
