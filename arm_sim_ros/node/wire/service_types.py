"""A ROS 2 service's request and response as cyclonedds IDL types, laid out as rmw_cyclonedds
(Jazzy) puts them on the wire, from the service's name and fields.

A service sample is the request or response struct with rmw_cyclonedds' request header in
front: `cdds_request_header_t {uint64 guid; int64 seq}` written straight after the 4-byte
encapsulation (rmw_cyclonedds_cpp/src/serdata.hpp; Serialization.cpp
`serialize_top_level(cursor, cdds_request_wrapper_t)`), so CDR alignment of the payload
counts from the start of the header. Here that header is the first two fields of each
struct (`guid`, `seq`); the bytes are the same. Type names are
`<pkg>::srv::dds_::<Srv>_Request_` / `_Response_` (ServiceTypeSupport_impl.hpp; an action's
services `<pkg>::action::dds_::<Action>_SendGoal_Request_` ...); structs are final and
keyless (XCDR1), as DESIGN.md's wire facts require. An empty struct gets rosidl's
`uint8 structure_needs_at_least_one_member`. (No `from __future__ import annotations`:
cyclonedds resolves field types at runtime.)
"""

import types
import typing
from dataclasses import dataclass, field

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.annotations import final
from cyclonedds.idl.types import int64, uint8, uint64

EMPTY = {"structure_needs_at_least_one_member": uint8}
HEADER = {"guid": uint64, "seq": int64}


def zero(kind):
    """The default of a field of this IDL type: 0, 0.0, False, "", an empty list or struct."""
    if isinstance(kind, type) and issubclass(kind, IdlStruct):
        return field(default_factory=kind)
    base = typing.get_args(kind)[0] if typing.get_origin(kind) is typing.Annotated else kind
    if typing.get_origin(base) is not None:        # sequence[...]
        return field(default_factory=list)
    return base()


def service(name: str, request: dict, response: dict, defaults=None) -> tuple:
    """(Request, Response) of the ROS 2 service `name` ("pkg/srv/Name", or
    "pkg/action/Name_SendGoal" for an action's): the header, then the fields in the order
    given ({field: IDL type}), each defaulting to its type's zero or to `defaults[field]`.
    Each type carries its ROS name (`ros_name`: "pkg/srv/Name_Request") for the type hash."""
    package, kind, base = name.split("/")
    made = []
    for part, fields in (("Request", request), ("Response", response)):
        fields = HEADER | (fields or EMPTY)
        namespace = {"__annotations__": fields, "ros_name": f"{name}_{part}"}
        namespace |= {key: (defaults or {}).get(key, zero(kind_)) for key, kind_ in fields.items()}
        struct = types.new_class(base.rpartition("_")[2] + part, (IdlStruct,),
                                 {"typename": f"{package}.{kind}.dds_.{base}_{part}_"},
                                 lambda body, namespace=namespace: body.update(namespace))
        made.append(final(dataclass(struct)))
    return tuple(made)


def ros_type_names(*pairs) -> dict:
    """{wire type: its ROS name} of service types made by `service`."""
    return {kind: kind.ros_name for pair in pairs for kind in pair}
