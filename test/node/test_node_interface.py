"""The node on the wire serves exactly what interface.py declares (and so what
docs/reference/node.md lists): every topic it publishes or takes, every service and the
action, by name and type, on the dds transport."""
import time

import pytest
from cyclonedds.builtin import (BuiltinDataReader, BuiltinTopicDcpsPublication,
                                BuiltinTopicDcpsSubscription)

from arm_sim_ros import interface
from arm_sim_ros.node.transports.dds import DdsArmSimNode
from arm_sim_ros.node.wire import messages as msg

from node.test_node_dds import CONFIG, TIMEOUT

INTERNAL = {"ros_discovery_info"}   # rmw's own graph topic, not the node's interface


def wire_name(name: str) -> str:
    """A declared name as the default node (/arm_sim) puts it on the wire."""
    return (f"{interface.NODE_NAME}/{name[2:]}" if name.startswith("~/")
            else name.lstrip("/"))


def dds_type(ros_type: str) -> str:
    package, kind, name = ros_type.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def declared() -> set:
    out = {(f"rt/{wire_name(n)}", dds_type(t)) for n, (t, _) in
           (interface.PUBLISHES | interface.SUBSCRIBES).items()}
    for name, (ros_type, _) in interface.SERVICES.items():
        out |= {(f"rq/{wire_name(name)}Request", dds_type(ros_type) + "Request_"),
                (f"rr/{wire_name(name)}Reply", dds_type(ros_type) + "Response_")}
    for name, (ros_type, _) in interface.ACTIONS.items():
        package, _, action = ros_type.split("/")
        for service in ("send_goal", "get_result"):
            kind = "".join(w.title() for w in service.split("_"))
            out |= {(f"rq/{name}/_action/{service}Request",
                     f"{package}::action::dds_::{action}_{kind}_Request_"),
                    (f"rr/{name}/_action/{service}Reply",
                     f"{package}::action::dds_::{action}_{kind}_Response_")}
        out |= {(f"rq/{name}/_action/cancel_goalRequest", "action_msgs::srv::dds_::CancelGoal_Request_"),
                (f"rr/{name}/_action/cancel_goalReply", "action_msgs::srv::dds_::CancelGoal_Response_"),
                (f"rt/{name}/_action/status", "action_msgs::msg::dds_::GoalStatusArray_"),
                (f"rt/{name}/_action/feedback",
                 f"{package}::action::dds_::{action}_FeedbackMessage_")}
    return out


def without_sensors() -> set:
    """What a node whose scene has no sensors serves: all but the truth beside readings."""
    return {(name, kind) for name, kind in declared()
            if name not in {f"rt/{wire_name(n)}" for n in interface.WITH_SENSORS}}


@pytest.mark.parametrize("parameters, served", [({}, without_sensors), (
    {"sensors.position_noise": [1e-4, 1e-4]}, declared)], ids=["release", "with sensors"])
def test_the_node_serves_exactly_the_declared_interface(parameters, served):
    domain = 131 if not parameters else 161
    node = DdsArmSimNode(parameters, domain_id=domain, config=CONFIG)
    peer = msg.make_participant(domain, CONFIG)
    try:
        seen, settled, deadline = set(), 0, time.monotonic() + TIMEOUT
        while settled < 20 and time.monotonic() < deadline:   # 0.2 s with nothing new
            before = len(seen)
            for builtin in (BuiltinTopicDcpsPublication, BuiltinTopicDcpsSubscription):
                seen |= {(s.topic_name, s.type_name) for s in
                         BuiltinDataReader(peer, builtin).read(N=500)
                         if s.participant_key != peer.guid and s.topic_name not in INTERNAL}
            settled = settled + 1 if len(seen) == before and seen else 0
            node.spin(0.01)
        assert seen == served()
    finally:
        node.close()
