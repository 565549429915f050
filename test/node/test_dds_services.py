"""The dds transport's ROS 2 services: the rcl_interfaces parameter services, ~/reset and
/parameter_events, on rmw_cyclonedds' wire (in-process, loopback only, domains 120-139).

The client here is built as rmw_cyclonedds builds one (rmw_node.cpp: rmw_init_cs,
rmw_send_request, rmw_take_response): a writer of `rq/<service>Request` and a reader of
`rr/<service>Reply` with USER_DATA `clientid=…;typehash=…;`, each request headed by
{request writer's instance handle, sequence number}, keeping only replies with its own handle.
Byte-level tests pin the format against hand-written CDR and the rosbags library; where ROS 2
is sourced, rclpy's own clients and the ros2 CLI talk to the node too.
"""
import json
import logging
import math
import os
import shutil
import subprocess
import sys
import time
from struct import pack

import numpy as np
import pytest
from cyclonedds.builtin import (BuiltinDataReader, BuiltinTopicDcpsPublication,
                                BuiltinTopicDcpsSubscription)
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from arm_sim_ros.node.wire import messages as msg
from arm_sim_ros.node.services import parameter_services as ps
from arm_sim_ros.node.core import ArmSimCore
from arm_sim_ros.node.params.parameters import PARAMETERS, SPECS, resolve_parameters
from arm_sim_ros.node.params.ros_args import node_identity, parse_ros_args
from arm_sim_ros.node.transports import dds_service_types as t
from arm_sim_ros.node.transports.dds import DdsArmSimNode
from arm_sim_ros.node.transports.dds_services import (cs_id, endpoint_qos, from_value, to_value,
                                                      user_data_value)
from arm_sim_ros.node.services.simulation import SERVICES as SIMULATION_SERVICES
from arm_sim_ros.node.transports.dds_action import SERVICES as ACTION_SERVICES
from arm_sim_ros.node.transports.dds_action import TYPE_HASHES as ACTION_HASHES
from arm_sim_ros.node.transports.dds_simulation import TYPE_HASHES as SIMULATION_HASHES
from arm_sim_ros.physics.scene import MAPPINGS
from node.test_node_dds import CONFIG, TIMEOUT, start as start_node, wait_until

U64 = (1 << 64) - 1

SERVICES = {   # service -> (request, response) wire types
    "list_parameters": (t.ListParametersRequest, t.ListParametersResponse),
    "get_parameters": (t.GetParametersRequest, t.GetParametersResponse),
    "set_parameters": (t.SetParametersRequest, t.SetParametersResponse),
    "set_parameters_atomically": (t.SetParametersAtomicallyRequest,
                                  t.SetParametersAtomicallyResponse),
    "describe_parameters": (t.DescribeParametersRequest, t.DescribeParametersResponse),
    "get_parameter_types": (t.GetParameterTypesRequest, t.GetParameterTypesResponse),
    "reset": (t.TriggerRequest, t.TriggerResponse),
}


class Client:
    """A service client on rmw_cyclonedds' wire."""
    count = 0

    def __init__(self, participant, service, node_name="/arm_sim", reply_reader=True,
                 types=None):
        Client.count += 1
        self.request_type, self.reply_type = types or SERVICES[service]
        self.user_data = f"clientid={cs_id(participant.guid.bytes, Client.count)};"
        p, name = participant, f"{node_name}/{service}"
        self.participant, self.name = p, name
        self.writer = DataWriter(p, Topic(p, f"rq{name}Request", self.request_type),
                                 qos=endpoint_qos(self.request_type, 10, self.user_data))
        self.reader = self.open_reply_reader() if reply_reader else None
        self.guid = self.writer.get_instance_handle() & U64   # rmw: header.guid = pubiid
        self.seq = 0

    def open_reply_reader(self):
        p = self.participant
        self.reader = DataReader(p, Topic(p, f"rr{self.name}Reply", self.reply_type),
                                 qos=endpoint_qos(self.reply_type, 10, self.user_data))
        return self.reader

    def wait_for_service(self):
        wait_until(lambda: msg.matched(self.writer) and msg.matched(self.reader),
                   f"{self.name} not discovered")

    def send(self, **fields) -> int:
        self.seq += 1
        self.writer.write(self.request_type(guid=self.guid, seq=self.seq, **fields))
        return self.seq

    def replies(self, node, count=1):
        """Replies to this client, serving the node meanwhile (it runs in this thread)."""
        received, deadline = [], time.monotonic() + TIMEOUT
        while len(received) < count and time.monotonic() < deadline:
            node.services.poll()
            received += [r for r in self.reader.take(N=100)
                         if isinstance(r, self.reply_type) and r.guid == self.guid]
            time.sleep(0.0005)
        assert len(received) == count, f"{self.name}: {len(received)} of {count} replies"
        return received

    def call(self, node, **fields):
        seq = self.send(**fields)
        reply, = self.replies(node)
        assert (reply.guid, reply.seq) == (self.guid, seq)
        return reply


OPEN = []   # the nodes a test started: closed after it


@pytest.fixture(autouse=True)
def close_nodes():
    yield
    while OPEN:
        OPEN.pop().close()


def opened(node):
    OPEN.append(node)
    return node


def start(domain_id, **parameters):
    """A node (test_node_dds.start) and the participant of a peer that talks to it."""
    node, peer = start_node(domain_id, **parameters)
    return opened(node), peer.participant


def clients(participant, *services):
    made = [Client(participant, service) for service in services]
    for client in made:
        client.wait_for_service()
    return made if len(made) > 1 else made[0]


def param(name, kind, value):
    return t.Parameter(name, to_value(kind, value))


# --- the services ------------------------------------------------------------------------------

def test_list_get_types_and_describe_answer_as_rclpy_does():
    node, p = start(120)
    lister, getter, typer, describer = clients(
        p, "list_parameters", "get_parameters", "get_parameter_types", "describe_parameters")
    result = lister.call(node, prefixes=[], depth=0).result
    assert result.names == [spec.name for spec in PARAMETERS]
    assert result.prefixes == list(MAPPINGS)        # friction.coulomb... as rclpy lists them
    assert lister.call(node, prefixes=["damping"], depth=0).result.names == ["damping"]
    assert lister.call(node, prefixes=["friction"], depth=0).result.names == [
        "friction.coulomb", "friction.static", "friction.stribeck_velocity"]
    assert lister.call(node, prefixes=["nothing"], depth=0).result.names == []

    names = ["damping", "joint_names", "scene", "rerun_spawn", "constant_torque", "publish_rate"]
    values = getter.call(node, names=names).values
    assert [v.type for v in values] == [ps.DOUBLE, ps.STRING_ARRAY, ps.STRING, ps.BOOL,
                                        ps.DOUBLE_ARRAY, ps.DOUBLE]
    assert [from_value(v) for v in values] == [0.0, ["shoulder_joint", "elbow_joint"], "release",
                                               False, [0.0, 0.0], 100.0]
    assert typer.call(node, names=names).types == [v.type for v in values]
    # rclpy, undeclared parameters not allowed: one unknown name empties the whole answer
    assert getter.call(node, names=["damping", "warp_speed"]).values == []
    assert typer.call(node, names=["warp_speed"]).types == []
    assert describer.call(node, names=["gravity", "warp_speed"]).descriptors == []

    scene, damping = describer.call(node, names=["scene", "damping"]).descriptors
    assert (scene.name, scene.type, scene.read_only, scene.dynamic_typing) == (
        "scene", ps.STRING, True, False)
    assert scene.description == SPECS["scene"].description
    assert (damping.type, damping.read_only, damping.dynamic_typing) == (ps.DOUBLE, False, True)
    assert damping.floating_point_range == [] and damping.integer_range == []


def test_scene_and_robot_description_are_read_only_as_the_rclpy_transport_declares_them():
    log = logging.getLogger("test_read_only")
    services = ps.ParameterServices(ArmSimCore(resolve_parameters({}), log), log)
    assert [(d.name, d.read_only, d.dynamic_typing) for d in services.describe(
        ["scene", "robot_description", "damping"])] == [
        ("scene", True, False), ("robot_description", True, False), ("damping", False, True)]
    for name in ("scene", "robot_description"):
        assert services.set_atomically([(name, "")]) == ps.SetResult(
            False, f"Trying to set a read-only parameter: {name}.")


def test_set_applies_each_parameter_on_its_own_and_publishes_an_event():
    node, p = start(121)
    setter, getter = clients(p, "set_parameters", "get_parameters")
    events = DataReader(p, Topic(p, "rt/parameter_events", t.ParameterEvent),
                        qos=endpoint_qos(t.ParameterEvent, 1000))
    wait_until(lambda: msg.matched(events), "parameter_events not matched")
    results = setter.call(node, parameters=[
        param("damping", ps.DOUBLE, 0.3),
        param("publish_rate", ps.INTEGER, 50),            # an integer is a fine double
        param("scene", ps.STRING, "damped_release"),
        param("warp_speed", ps.DOUBLE, 9.0),
        param("gravity", ps.DOUBLE, math.nan),
        param("torque_limit", ps.NOT_SET, None),
    ]).results
    assert [r.successful for r in results] == [True, True, False, False, False, False]
    assert results[2].reason == "Trying to set a read-only parameter: scene."
    assert results[3].reason == "Invalid access to undeclared parameter(s): ['warp_speed']"
    assert "parameter 'gravity' refused" in results[4].reason and "not finite" in results[4].reason
    assert "parameter 'torque_limit' refused" in results[5].reason
    values = node.core.config.values
    assert (values["damping"], values["publish_rate"], values["gravity"]) == (0.3, 50.0, 9.81)
    assert [from_value(v) for v in getter.call(node, names=["publish_rate"]).values] == [50.0]

    received, deadline = [], time.monotonic() + TIMEOUT
    while len(received) < 2 and time.monotonic() < deadline:
        received += [e for e in events.take(N=10) if isinstance(e, t.ParameterEvent)]
    first, second = received
    assert first.node == "/arm_sim" and first.new_parameters == first.deleted_parameters == []
    assert [(c.name, from_value(c.value)) for c in first.changed_parameters] == [("damping", 0.3)]
    assert [(c.name, c.value.type, from_value(c.value)) for c in second.changed_parameters] == [
        ("publish_rate", ps.DOUBLE, 50.0)]
    assert abs(first.stamp.sec - time.time()) < 60


def test_set_atomically_is_all_or_nothing():
    node, p = start(122)
    atomic, typer = clients(p, "set_parameters_atomically", "get_parameter_types")
    before = dict(node.core.config.values)
    result = atomic.call(node, parameters=[
        param("damping", ps.DOUBLE, 0.2), param("link_masses", ps.DOUBLE_ARRAY, [1.0, 0.0])]).result
    assert not result.successful and "link_masses" in result.reason
    assert node.core.config.values == before
    result = atomic.call(node, parameters=[param("damping", ps.INTEGER_ARRAY, [1, 2]),
                                           param("gravity", ps.INTEGER, 0)]).result
    assert result.successful and result.reason == ""
    assert node.core.config.values["damping"] == [1.0, 2.0]
    assert node.core.config.values["gravity"] == 0.0
    # a damping given as a pair is served as a double array from now on
    assert typer.call(node, names=["damping", "gravity"]).types == [ps.DOUBLE_ARRAY, ps.DOUBLE]


def test_effects_are_parameters_on_the_wire_live_ones_set_start_only_ones_refused():
    node, p = start(126, scene="stick_slip")
    setter, getter, atomic = clients(p, "set_parameters", "get_parameters",
                                     "set_parameters_atomically")
    values = getter.call(node, names=["friction.coulomb", "friction.static", "effort_limits",
                                      "motors.gear_ratio"]).values
    assert [(v.type, from_value(v)) for v in values] == [
        (ps.DOUBLE_ARRAY, [3.0, 0.5]), (ps.DOUBLE_ARRAY, [4.0, 0.8]),
        (ps.NOT_SET, None), (ps.NOT_SET, None)]          # not named by the scene: absent
    for _ in range(5):
        node.tick()
    steps = node.core.sim.steps
    results = setter.call(node, parameters=[
        param("effort_limits", ps.INTEGER_ARRAY, [15, 10]),
        param("friction.static", ps.DOUBLE_ARRAY, [1.0, 1.0]),
        param("motors.gear_ratio", ps.DOUBLE_ARRAY, [10.0, 10.0]),
        param("friction.coulomb", ps.DOUBLE_ARRAY, [2.0, 0.4]),
    ]).results
    assert [r.successful for r in results] == [True, False, False, True]
    assert "parameter 'friction.static' refused" in results[1].reason and \
        "breakaway needs Fs >= Fc" in results[1].reason
    assert "parameter 'motors.gear_ratio' refused: motors.gear_ratio is start-only" in \
        results[2].reason
    scene = node.core.sim.scene
    assert scene.effort_limits == (15.0, 10.0) and scene.friction["coulomb"] == (2.0, 0.4)
    assert node.core.sim.steps == steps            # carried on: not restarted
    before = node.core.config.values
    result = atomic.call(node, parameters=[
        param("effort_limits", ps.DOUBLE_ARRAY, [5.0, 5.0]),
        param("controller_model.link_masses", ps.DOUBLE_ARRAY, [1.0, -1.0])]).result
    assert not result.successful and "controller_model.link_masses" in result.reason
    assert node.core.config.values == before


def test_reset_restarts_the_scene():
    node, p = start(123, initial_positions=[0.4, 0.0])
    reset = clients(p, "reset")
    for _ in range(5):
        node.tick()
    assert node.core.sim.steps > 0
    reply = reset.call(node)
    assert reply.success and reply.message == "scene release restarted from its initial state"
    assert node.core.sim.steps == 0 and list(node.core.sim.state[:2]) == [0.4, 0.0]


def test_each_reply_echoes_its_clients_guid_and_sequence_number():
    node, p = start(124)
    first, second = clients(p, "get_parameters", "get_parameters")
    assert first.guid != second.guid
    first.seq = 41                                   # any numbering: the service echoes it
    seqs = [first.send(names=["gravity"]), second.send(names=["damping"]),
            first.send(names=["damping"])]
    a1, a2 = first.replies(node, 2)
    b, = second.replies(node)
    assert [(r.guid, r.seq) for r in (a1, a2, b)] == [
        (first.guid, seqs[0]), (first.guid, seqs[2]), (second.guid, seqs[1])]
    assert from_value(a1.values[0]) == 9.81 and from_value(b.values[0]) == 0.0


def test_a_reply_waits_until_its_clients_reply_reader_is_matched():
    """rmw_send_response: the reply goes out only once the client's reader (same clientid) is
    matched; here it is kept pending meanwhile instead of being lost."""
    node, p = start(125)
    client = Client(p, "get_parameters", reply_reader=False)
    wait_until(lambda: msg.matched(client.writer), "the request writer not matched")
    seq = client.send(names=["gravity"])

    def kept_pending():
        node.services.poll()
        return node.services.pending

    wait_until(kept_pending, "the request was not kept pending", poll=0)
    client.open_reply_reader()
    reply, = client.replies(node)
    assert reply.seq == seq and not node.services.pending


def test_a_request_whose_client_has_left_is_dropped():
    node, p = start(129)
    client = clients(p, "get_parameters")
    client.send(names=["gravity"])
    wait_until(lambda: node.services.waitset.wait(0), "the request did not arrive")
    client.writer = client.reader = None              # cyclonedds deletes both
    wait_until(lambda: not node.services.endpoints[1].reader.get_matched_publications(),
               "the client did not leave")
    assert node.services.poll() == 0 and node.services.pending == []


def test_a_ready_client_is_not_asked_about_again_while_the_matches_stand(monkeypatch):
    """cyclonedds-python 11.0.1 leaks ~100 B of native memory per get_matched_*_data: a node
    asking it at every request grew ~0.4 kB per set without end (bench_soak)."""
    node, p = start(136)
    client = clients(p, "get_parameters")
    endpoint = next(e for e in node.services.endpoints if e.name.endswith("get_parameters"))
    asked = []
    for side in (endpoint.reader, endpoint.writer):
        for name in ("get_matched_publication_data", "get_matched_subscription_data"):
            if hasattr(side, name):
                original = getattr(side, name)
                monkeypatch.setattr(side, name, lambda handle, f=original: asked.append(1) or f(handle))
    for _ in range(20):
        client.call(node, names=["gravity"])
    assert 0 < len(asked) <= 2 * 2      # the first request asks; the next 19 do not


def test_a_request_the_node_cannot_answer_is_logged_and_the_node_goes_on(caplog, monkeypatch):
    node, p = start(132)
    lister, getter = clients(p, "list_parameters", "get_parameters")

    def broken(prefixes, depth):
        raise RuntimeError("boom")

    monkeypatch.setattr(node.services.parameters, "list", broken)
    seq = lister.send(prefixes=[], depth=0)
    said = f"/arm_sim/list_parameters: request {seq} not answered: RuntimeError('boom')"

    def logged():
        node.services.poll()
        return any(said in r.getMessage() for r in caplog.records)

    with caplog.at_level("ERROR"):
        wait_until(logged, "the failed request was not logged")
    assert from_value(getter.call(node, names=["gravity"]).values[0]) == 9.81
    node.tick()
    assert lister.reader.take(N=10) == []


def test_a_request_in_a_spinning_node_is_answered_while_it_sleeps_between_ticks():
    import threading
    node = opened(DdsArmSimNode({"publish_rate": 5.0, "step_size": 0.01}, domain_id=135,
                                config=CONFIG))
    p = msg.make_participant(135, CONFIG)
    client = clients(p, "get_parameters")
    answered = []

    def ask():
        seq = client.send(names=["publish_rate"])
        deadline = time.monotonic() + TIMEOUT
        while not answered and time.monotonic() < deadline:
            answered.extend(r for r in client.reader.take(N=10)
                            if isinstance(r, t.GetParametersResponse) and r.seq == seq)
            time.sleep(0.001)
        answered.append(time.monotonic())

    asker = threading.Thread(target=ask)
    started = time.monotonic()
    asker.start()
    node.spin(0.4)                       # 2 ticks 200 ms apart
    asker.join()
    reply, when = answered
    assert from_value(reply.values[0]) == 5.0 and when - started < 0.15   # before the 2nd tick


def test_discovery_info_lists_every_service_endpoint_under_the_node():
    node, p = start(127)
    reader = DataReader(p, Topic(p, "ros_discovery_info", msg.ParticipantEntitiesInfo),
                        qos=msg.discovery_info_qos())
    infos = wait_until(lambda: [s for s in reader.take(N=5)
                                if isinstance(s, msg.ParticipantEntitiesInfo)],
                       "the node's ros_discovery_info did not arrive", poll=0)
    entry, = infos[0].node_entities_info_seq
    readers = {bytes(g.data) for g in entry.reader_gid_seq}
    writers = {bytes(g.data) for g in entry.writer_gid_seq}
    # what a peer discovers: every endpoint's topic, type name and USER_DATA, by GUID
    subscriptions, publications = {}, {}
    deadline = time.monotonic() + TIMEOUT
    while (len(subscriptions) < len(readers) or len(publications) < len(writers)) \
            and time.monotonic() < deadline:
        for found, builtin in ((subscriptions, BuiltinTopicDcpsSubscription),
                               (publications, BuiltinTopicDcpsPublication)):
            for s in BuiltinDataReader(p, builtin).read(N=200):
                if s.key.bytes in (readers | writers):
                    found[s.key.bytes] = s
        time.sleep(0.01)
    requests = {s.topic_name: s for g, s in subscriptions.items() if g in readers}
    replies = {s.topic_name: s for g, s in publications.items() if g in writers}
    for service, (request_type, reply_type) in SERVICES.items():
        request = requests[f"rq/arm_sim/{service}Request"]
        reply = replies[f"rr/arm_sim/{service}Reply"]
        assert request.type_name == request_type.__idl__.idl_transformed_typename
        assert reply.type_name == reply_type.__idl__.idl_transformed_typename
        service_id = user_data_value(request.qos, "serviceid")
        assert service_id and user_data_value(reply.qos, "serviceid") == service_id
        assert user_data_value(reply.qos, "typehash") == t.TYPE_HASHES[t.ROS_TYPE_NAMES[reply_type]]
    assert requests["rq/arm_sim/get_parametersRequest"].type_name == \
        "rcl_interfaces::srv::dds_::GetParameters_Request_"
    assert requests["rq/arm_sim/resetRequest"].type_name == "std_srvs::srv::dds_::Trigger_Request_"
    assert replies["rt/parameter_events"].type_name == "rcl_interfaces::msg::dds_::ParameterEvent_"
    for service in SIMULATION_SERVICES + ACTION_SERVICES:   # under the namespace, not ~/
        hash_of = user_data_value(requests[f"rq/{service}Request"].qos, "typehash")
        assert hash_of in (SIMULATION_HASHES | ACTION_HASHES).values()
        assert f"rr/{service}Reply" in replies
    assert replies["rt/simulate_steps/_action/status"].type_name == \
        "action_msgs::msg::dds_::GoalStatusArray_"
    assert replies["rt/simulate_steps/_action/feedback"].type_name == \
        "simulation_interfaces::action::dds_::SimulateSteps_FeedbackMessage_"
    assert len({user_data_value(s.qos, "serviceid") for s in requests.values()
                if s.topic_name.startswith("rq/")}) == len(SERVICES) + len(
        SIMULATION_SERVICES) + len(ACTION_SERVICES)


def test_service_names_follow_the_namespace():
    node = opened(DdsArmSimNode({}, domain_id=128, config=CONFIG, namespace="/robot"))
    assert node.services.node == "/robot/arm_sim"
    assert {e.reader.topic.name for e in node.services.endpoints} == {
        f"rq/robot/arm_sim/{s}Request" for s in SERVICES} | {
        f"rq/robot/{s}Request" for s in SIMULATION_SERVICES + ACTION_SERVICES}


def remapped(domain_id, *rules):
    """A node started with `--ros-args -r RULE ...`, as arm_sim_node reads them."""
    name, namespace, remap = node_identity(parse_ros_args(
        [arg for rule in rules for arg in ("-r", rule)])["remap"])
    node = opened(DdsArmSimNode({}, domain_id=domain_id, config=CONFIG, name=name,
                                namespace=namespace, remap=remap))
    return node, msg.make_participant(domain_id, CONFIG)


def test_a_remapped_node_serves_its_parameters_and_reset_under_its_new_name():
    node, p = remapped(133, "__node:=other", "__ns:=/ns")
    assert node.services.node == "/ns/other"
    assert {e.reader.topic.name for e in node.services.endpoints} == {
        f"rq/ns/other/{s}Request" for s in SERVICES} | {
        f"rq/ns/{s}Request" for s in SIMULATION_SERVICES + ACTION_SERVICES}
    getter = Client(p, "get_parameters", node_name="/ns/other")
    reset = Client(p, "reset", node_name="/ns/other")
    for client in (getter, reset):
        client.wait_for_service()
    assert [from_value(v) for v in getter.call(node, names=["gravity"]).values] == [9.81]
    assert reset.call(node).success


def test_service_and_event_names_follow_remap_rules_as_topic_names_do():
    node, _ = remapped(134, "arm_sim:__node:=left", "~/reset:=/restart_left",
                       "other:__node:=ignored", "/parameter_events:=/left_events")
    topics = {e.reader.topic.name for e in node.services.endpoints}
    assert "rq/restart_leftRequest" in topics and "rq/left/get_parametersRequest" in topics
    assert node.services.events_writer.topic.name == "rt/left_events"


# --- bytes on the wire -----------------------------------------------------------------------

def cdr_string(text: str, offset: int) -> bytes:
    """A CDR string at `offset` from the start of the body: padding to 4, length, text, NUL."""
    data = text.encode() + b"\0"
    return bytes(-offset % 4) + pack("<I", len(data)) + data


def test_get_parameters_request_bytes_are_rmw_cyclonedds_request_bytes():
    """Serialization.cpp serialize_top_level(cdds_request_wrapper_t): the encapsulation
    (PLAIN_CDR, little-endian), guid and seq as two raw 8-byte words, then the request, with
    alignment counted from the end of the encapsulation."""
    request = t.GetParametersRequest(guid=0x1122334455667788, seq=7,
                                     names=["damping", "publish_rate"])
    body = pack("<QqI", 0x1122334455667788, 7, 2)
    body += cdr_string("damping", len(body))
    body += cdr_string("publish_rate", len(body))
    assert request.serialize() == b"\x00\x01\x00\x00" + body
    assert t.GetParametersRequest.deserialize(b"\x00\x01\x00\x00" + body) == request


def test_get_parameters_response_bytes_align_the_payload_after_the_header():
    reply = t.GetParametersResponse(guid=3, seq=-1, values=[to_value(ps.DOUBLE, 0.3)])
    body = pack("<QqI", 3, -1, 1)                    # 20 bytes
    body += pack("<B?", ps.DOUBLE, False) + bytes(2)  # type, bool_value, pad to 24
    body += pack("<qd", 0, 0.3)                       # integer_value, double_value: 40
    body += cdr_string("", len(body))                 # string_value: 45
    body += bytes(3) + pack("<5I", 0, 0, 0, 0, 0)     # five empty arrays: 68
    assert reply.serialize() == b"\x00\x01\x00\x00" + body


SRV_DEFINITIONS = {   # rcl_interfaces (jazzy) srv/*.srv, std_srvs/srv/Trigger.srv
    "rcl_interfaces/srv/ListParameters": (
        "uint64 DEPTH_RECURSIVE=0\nstring[] prefixes\nuint64 depth",
        "rcl_interfaces/ListParametersResult result"),
    "rcl_interfaces/srv/GetParameters": ("string[] names",
                                         "rcl_interfaces/ParameterValue[] values"),
    "rcl_interfaces/srv/SetParameters": ("rcl_interfaces/Parameter[] parameters",
                                         "rcl_interfaces/SetParametersResult[] results"),
    "rcl_interfaces/srv/SetParametersAtomically": ("rcl_interfaces/Parameter[] parameters",
                                                   "rcl_interfaces/SetParametersResult result"),
    "rcl_interfaces/srv/DescribeParameters": (
        "string[] names", "rcl_interfaces/ParameterDescriptor[] descriptors"),
    "rcl_interfaces/srv/GetParameterTypes": ("string[] names", "uint8[] types"),
    "std_srvs/srv/Trigger": ("", "bool success\nstring message"),
}


def service_store():
    """rosbags' Jazzy store with the request/response messages under their rosidl names."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for service, (request, response) in SRV_DEFINITIONS.items():
        for suffix, text in (("_Request", request), ("_Response", response)):
            (_, definition), = get_types_from_msg(text, service + suffix).items()
            types[service + suffix] = definition
    store.register(types)
    return store


def test_type_hashes_are_rosidls():
    store = service_store()
    assert {name: store.hash_rihs01(name) for name in t.TYPE_HASHES} == t.TYPE_HASHES
    # independent references: hashes in rosidl-generated code for Jazzy
    assert t.TYPE_HASHES["rcl_interfaces/srv/GetParameters_Request"].endswith(
        "135a9e1c3d7cebef792f6687d7ddf99949b21a0bd9a320d863a9110a3f5cf4d6")
    assert t.TYPE_HASHES["std_srvs/srv/Trigger_Request"].endswith(
        "d010825374ce8918e72bfd826c82603e60f45419e932ea976f807b74a863a199")
    assert t.TYPE_HASHES["rcl_interfaces/srv/SetParametersAtomically_Request"].endswith(
        "db0bd950ed5ed867a0e90b225e44dea382d762c0762ff3e0ee842190042a59e5")


def _rosbags_value(store, kind, value):
    T = store.types
    fields = dict(type=kind, bool_value=False, integer_value=0, double_value=0.0,
                  string_value="", byte_array_value=np.array([], dtype=np.uint8),
                  bool_array_value=np.array([], dtype=bool),
                  integer_array_value=np.array([], dtype=np.int64),
                  double_array_value=np.array([], dtype=np.float64), string_array_value=[])
    name = {ps.BOOL: "bool_value", ps.DOUBLE: "double_value", ps.STRING: "string_value",
            ps.DOUBLE_ARRAY: "double_array_value", ps.STRING_ARRAY: "string_array_value",
            ps.INTEGER: "integer_value"}[kind]
    fields[name] = np.array(value, dtype=np.float64) if kind == ps.DOUBLE_ARRAY else value
    return T["rcl_interfaces/msg/ParameterValue"](**fields)


def test_every_service_payload_is_rosbags_cdr_with_the_request_header_in_front():
    store = service_store()
    T = store.types
    values = [(ps.DOUBLE, 0.3), (ps.STRING, "rk4"), (ps.BOOL, True),
              (ps.DOUBLE_ARRAY, [0.1, -2.5]), (ps.STRING_ARRAY, ["a", "bc"]), (ps.INTEGER, 7)]
    cases = [
        (t.GetParametersResponse(values=[to_value(k, v) for k, v in values]),
         T["rcl_interfaces/srv/GetParameters_Response"](
             values=[_rosbags_value(store, k, v) for k, v in values])),
        (t.SetParametersRequest(parameters=[param("damping", ps.DOUBLE_ARRAY, [0.5, 0.25])]),
         T["rcl_interfaces/srv/SetParameters_Request"](parameters=[
             T["rcl_interfaces/msg/Parameter"](
                 name="damping", value=_rosbags_value(store, ps.DOUBLE_ARRAY, [0.5, 0.25]))])),
        (t.DescribeParametersResponse(descriptors=[t.ParameterDescriptor(
            name="scene", type=ps.STRING, description="d", read_only=True,
            floating_point_range=[t.FloatingPointRange(0.0, 1.0, 0.5)])]),
         T["rcl_interfaces/srv/DescribeParameters_Response"](descriptors=[
             T["rcl_interfaces/msg/ParameterDescriptor"](
                 name="scene", type=ps.STRING, description="d", additional_constraints="",
                 read_only=True, dynamic_typing=False,
                 floating_point_range=[T["rcl_interfaces/msg/FloatingPointRange"](0.0, 1.0, 0.5)],
                 integer_range=[])])),
        (t.ListParametersRequest(prefixes=["a"], depth=3),
         T["rcl_interfaces/srv/ListParameters_Request"](prefixes=["a"], depth=3)),
        (t.GetParameterTypesResponse(types=[3, 8, 9]),
         T["rcl_interfaces/srv/GetParameterTypes_Response"](
             types=np.array([3, 8, 9], dtype=np.uint8))),
        (t.TriggerRequest(),
         T["std_srvs/srv/Trigger_Request"](structure_needs_at_least_one_member=0)),
        (t.TriggerResponse(success=True, message="ok"),
         T["std_srvs/srv/Trigger_Response"](success=True, message="ok")),
    ]
    for ours, reference in cases:
        ours.guid, ours.seq = 0xFEDCBA9876543210, 12
        cdr = bytes(store.serialize_cdr(reference, reference.__msgtype__))
        assert ours.serialize() == cdr[:4] + pack("<Qq", 0xFEDCBA9876543210, 12) + cdr[4:], \
            reference.__msgtype__


def test_parameter_event_bytes_equal_rosbags():
    store = get_typestore(Stores.ROS2_JAZZY)
    T = store.types
    event = t.ParameterEvent(stamp=msg.Time(3, 4), node="/arm_sim",
                             changed_parameters=[param("gravity", ps.DOUBLE, 1.5)])
    reference = T["rcl_interfaces/msg/ParameterEvent"](
        stamp=T["builtin_interfaces/msg/Time"](sec=3, nanosec=4), node="/arm_sim",
        new_parameters=[], deleted_parameters=[],
        changed_parameters=[T["rcl_interfaces/msg/Parameter"](
            name="gravity", value=_rosbags_value(store, ps.DOUBLE, 1.5))])
    assert event.serialize() == bytes(store.serialize_cdr(reference,
                                                          "rcl_interfaces/msg/ParameterEvent"))


def test_service_ids_print_as_rmw_cyclonedds_prints_them():
    guid = bytes([0x01, 0x10, 0xab] + [0] * 9 + [0xde, 0xad, 0xbe, 0xef])
    assert cs_id(guid, 258) == " 1.10.ab.0.0.0.0.0.0.0.0.0.0.0.1.2"


@pytest.mark.parametrize("kind, value", [
    (ps.BOOL, True), (ps.INTEGER, -3), (ps.DOUBLE, 2.5), (ps.STRING, "x"),
    (ps.DOUBLE_ARRAY, [1.0, 2.0]), (ps.STRING_ARRAY, ["a"]), (ps.INTEGER_ARRAY, [1, 2]),
    (ps.BOOL_ARRAY, [True, False]), (ps.BYTE_ARRAY, [1, 255]), (ps.NOT_SET, None)])
def test_parameter_values_round_trip(kind, value):
    wire = t.ParameterValue.deserialize(to_value(kind, value).serialize())
    assert (wire.type, from_value(wire)) == (kind, value)


# --- against ROS 2 itself, where it is sourced ----------------------------------------------------

ROS_CHILD = r"""
import json, sys
import rclpy
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from std_srvs.srv import Trigger

rclpy.init()
node = rclpy.create_node("dds_services_probe")
def done(future):
    rclpy.spin_until_future_complete(node, future, timeout_sec=10.0)
    return future.result()
client = AsyncParameterClient(node, "/arm_sim")
assert client.wait_for_services(timeout_sec=10.0), "parameter services not found"
out = {"names": list(done(client.list_parameters()).result.names)}
value = done(client.get_parameters(["damping"])).values[0]
out["damping"] = [value.type, value.double_value]
results = done(client.set_parameters([Parameter("damping", value=0.3),
                                      Parameter("scene", value="x")])).results
out["set"] = [[r.successful, r.reason] for r in results]
out["describe"] = [[d.name, d.read_only] for d in
                   done(client.describe_parameters(["scene"])).descriptors]
reset = node.create_client(Trigger, "/arm_sim/reset")
assert reset.wait_for_service(timeout_sec=10.0)
out["reset"] = done(reset.call_async(Trigger.Request())).success
print(json.dumps(out))
"""


def need_rmw_cyclonedds():
    """These tests speak to ROS 2 on rmw_cyclonedds; skip where it is not installed."""
    ament = pytest.importorskip("ament_index_python.packages")
    try:
        ament.get_package_prefix("rmw_cyclonedds_cpp")
    except ament.PackageNotFoundError:
        pytest.skip("rmw_cyclonedds_cpp is not installed")


def ros_environment(domain):
    return dict(os.environ, ROS_DOMAIN_ID=str(domain), RMW_IMPLEMENTATION="rmw_cyclonedds_cpp",
                ROS_AUTOMATIC_DISCOVERY_RANGE="SYSTEM_DEFAULT", CYCLONEDDS_URI=CONFIG)


def serve_while(node, process, timeout=60.0):
    deadline = time.monotonic() + timeout
    while process.poll() is None and time.monotonic() < deadline:
        node.services.serve_for(0.02)
    out, err = process.communicate(timeout=5)
    return out, err


def test_rclpy_parameter_client_and_trigger_client_against_the_dds_node():
    pytest.importorskip("rclpy")
    pytest.importorskip("std_srvs.srv")
    need_rmw_cyclonedds()
    node, _ = start(130)
    process = subprocess.Popen([sys.executable, "-c", ROS_CHILD], env=ros_environment(130),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, err = serve_while(node, process)
    assert process.returncode == 0, err
    result = json.loads(out.strip().splitlines()[-1])
    assert set(SPECS) <= set(result["names"])
    assert result["damping"] == [ps.DOUBLE, 0.0]
    assert result["set"] == [[True, ""], [False, "Trying to set a read-only parameter: scene."]]
    assert result["describe"] == [["scene", True]] and result["reset"] is True
    assert node.core.config.values["damping"] == 0.3


def test_ros2_cli_param_and_service_call_against_the_dds_node():
    if shutil.which("ros2") is None:
        pytest.skip("ros2 CLI not on PATH (ROS 2 not sourced)")
    need_rmw_cyclonedds()
    node, _ = start(131)
    env = ros_environment(131)
    commands = {
        "list": ["ros2", "param", "list", "/arm_sim", "--no-daemon", "--spin-time", "3"],
        "set": ["ros2", "param", "set", "/arm_sim", "damping", "0.3", "--no-daemon",
                "--spin-time", "3"],
        "get": ["ros2", "param", "get", "/arm_sim", "damping", "--no-daemon", "--spin-time", "3"],
        "reset": ["ros2", "service", "call", "/arm_sim/reset", "std_srvs/srv/Trigger"],
    }
    outputs = {}
    for name, command in commands.items():
        process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, text=True)
        outputs[name], err = serve_while(node, process)
        assert process.returncode == 0, (name, err)
    assert "  damping" in outputs["list"] and "  scene" in outputs["list"]
    assert "Set parameter successful" in outputs["set"]
    assert "Double value is: 0.3" in outputs["get"]
    assert "success=True" in outputs["reset"]
