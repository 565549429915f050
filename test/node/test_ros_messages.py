"""The cyclonedds message types produce the same CDR bytes and type hashes as ROS 2 Jazzy
(the rosbags library's Jazzy typestore is the independent reference)."""
import math

import numpy as np
import pytest
from cyclonedds.idl import IdlStruct
from hypothesis import given, settings, strategies as st
from rosbags.typesys import Stores, get_typestore

from arm_sim_ros.node.wire import messages as m
from arm_sim_ros.node.wire.cdr import joint_state_bytes

STORE = get_typestore(Stores.ROS2_JAZZY)
T = STORE.types


def reference_joint_state():
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=12, nanosec=345),
                                      frame_id="world")
    return T["sensor_msgs/msg/JointState"](
        header=header, name=["shoulder_joint", "elbow_joint"],
        position=np.array([-1.25, 7.5]), velocity=np.array([0.1, -2.0]),
        effort=np.array([1.0, -math.pi]))


def ours_joint_state():
    return m.JointState(header=m.Header(stamp=m.Time(sec=12, nanosec=345), frame_id="world"),
                        name=["shoulder_joint", "elbow_joint"], position=[-1.25, 7.5],
                        velocity=[0.1, -2.0], effort=[1.0, -math.pi])


def test_joint_state_bytes_equal_rosbags():
    expected = bytes(STORE.serialize_cdr(reference_joint_state(), "sensor_msgs/msg/JointState"))
    assert ours_joint_state().serialize() == expected


doubles = st.lists(st.floats(allow_nan=False, width=64), max_size=4)
names = st.lists(st.text(max_size=12), max_size=4)


@settings(max_examples=50, deadline=None, derandomize=True)   # 150 took 14 s loaded
@given(sec=st.integers(-2**31, 2**31 - 1), nanosec=st.integers(0, 2**32 - 1),
       frame_id=st.text(max_size=9), name=names, position=doubles, velocity=doubles,
       effort=doubles)
def test_fast_joint_state_encoder_writes_the_generic_and_rosbags_bytes(
        sec, nanosec, frame_id, name, position, velocity, effort):
    ours = m.JointState(header=m.Header(stamp=m.Time(sec, nanosec), frame_id=frame_id),
                        name=name, position=position, velocity=velocity, effort=effort)
    reference = T["sensor_msgs/msg/JointState"](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](
            sec=sec, nanosec=nanosec), frame_id=frame_id),
        name=name, position=np.array(position, dtype=np.float64),
        velocity=np.array(velocity, dtype=np.float64), effort=np.array(effort, dtype=np.float64))
    fast = ours.serialize()
    assert fast == IdlStruct.serialize(ours)            # cyclonedds' own generic serializer
    assert fast == bytes(STORE.serialize_cdr(reference, "sensor_msgs/msg/JointState"))
    assert m.JointState.deserialize(fast) == ours
    assert len(fast) % 4 == 0                           # as DataWriter.write pads: write_cdr
    assert joint_state_bytes(sec, nanosec, frame_id, name, position, velocity, effort) == fast


@settings(max_examples=100, deadline=None, derandomize=True)
@given(sec=st.integers(-2**31, 2**31 - 1), nanosec=st.integers(0, 2**32 - 1))
def test_fast_clock_encoder_writes_the_generic_and_rosbags_bytes(sec, nanosec):
    ours = m.Clock(m.Time(sec, nanosec))
    reference = T["rosgraph_msgs/msg/Clock"](clock=T["builtin_interfaces/msg/Time"](
        sec=sec, nanosec=nanosec))
    fast = ours.serialize()
    assert fast == IdlStruct.serialize(ours)            # cyclonedds' own generic serializer
    assert fast == bytes(STORE.serialize_cdr(reference, "rosgraph_msgs/msg/Clock"))
    assert m.Clock.deserialize(fast) == ours


def test_float64_multi_array_bytes_equal_rosbags_both_ways():
    layout = T["std_msgs/msg/MultiArrayLayout"](
        dim=[T["std_msgs/msg/MultiArrayDimension"](label="joints", size=2, stride=2)], data_offset=0)
    reference = T["std_msgs/msg/Float64MultiArray"](layout=layout, data=np.array([1.5, -0.25]))
    expected = bytes(STORE.serialize_cdr(reference, "std_msgs/msg/Float64MultiArray"))
    ours = m.Float64MultiArray(layout=m.MultiArrayLayout(
        dim=[m.MultiArrayDimension(label="joints", size=2, stride=2)]), data=[1.5, -0.25])
    assert ours.serialize() == expected
    assert m.Float64MultiArray.deserialize(expected) == ours


def test_diagnostic_array_bytes_equal_rosbags():
    status = T["diagnostic_msgs/msg/DiagnosticStatus"](
        level=bytes([1])[0], name="arm_sim: simulation", message="late ticks", hardware_id="sim",
        values=[T["diagnostic_msgs/msg/KeyValue"](key="refused_commands", value="3")])
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=2),
                                      frame_id="")
    reference = T["diagnostic_msgs/msg/DiagnosticArray"](header=header, status=[status])
    expected = bytes(STORE.serialize_cdr(reference, "diagnostic_msgs/msg/DiagnosticArray"))
    ours = m.DiagnosticArray(
        header=m.Header(stamp=m.Time(sec=1, nanosec=2)),
        status=[m.DiagnosticStatus(level=m.DiagnosticStatus.WARN, name="arm_sim: simulation",
                                   message="late ticks", hardware_id="sim",
                                   values=[m.KeyValue(key="refused_commands", value="3")])])
    assert ours.serialize() == expected


def test_participant_entities_info_bytes_equal_rosbags():
    gid = T["rmw_dds_common/msg/Gid"]
    reference = T["rmw_dds_common/msg/ParticipantEntitiesInfo"](
        gid=gid(data=np.arange(16, dtype=np.uint8)),
        node_entities_info_seq=[T["rmw_dds_common/msg/NodeEntitiesInfo"](
            node_namespace="/", node_name="arm_sim",
            reader_gid_seq=[gid(data=np.full(16, 7, dtype=np.uint8))], writer_gid_seq=[])])
    expected = bytes(STORE.serialize_cdr(reference, "rmw_dds_common/msg/ParticipantEntitiesInfo"))
    ours = m.ParticipantEntitiesInfo(
        gid=m.Gid(list(range(16))),
        node_entities_info_seq=[m.NodeEntitiesInfo("/", "arm_sim", [m.Gid([7] * 16)], [])])
    assert ours.serialize() == expected


@pytest.mark.parametrize("ros_name", sorted(m.TYPE_HASHES))
def test_type_hash_equals_rosbags(ros_name):
    assert m.TYPE_HASHES[ros_name] == STORE.hash_rihs01(ros_name)


def test_type_names_follow_ros_dds_convention():
    for message_type, ros_name in m.ROS_TYPE_NAMES.items():
        package, kind, name = ros_name.split("/")
        assert message_type.__idl_typename__ == f"{package}.{kind}.dds_.{name}_"


def test_endpoint_qos_carries_the_type_hash():
    qos = m.default_qos(m.JointState)
    user_data = [p for p in qos if type(p).__name__ == "Userdata"][0].data
    assert user_data == f"typehash={STORE.hash_rihs01('sensor_msgs/msg/JointState')};".encode()


def test_topic_names_get_the_ros_prefix():
    assert m.ros_topic("joint_states") == "rt/joint_states"
    assert m.ros_topic("/diagnostics") == "rt/diagnostics"


def test_discovery_defaults_to_subnet_with_nothing_added():
    assert m.discovery_config({}) == ""
    assert m.discovery_config({"CYCLONEDDS_URI": "file:///x.xml"}) == "file:///x.xml"


def test_localhost_range_disables_multicast_and_peers_localhost_then_user_config():
    text = m.discovery_config({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                               "ROS_STATIC_PEERS": "10.0.0.2; localhost",
                               "CYCLONEDDS_URI": "file:///user.xml"})
    assert "<AllowMulticast>false</AllowMulticast>" in text
    assert '<Peers><Peer address="localhost"/><Peer address="10.0.0.2"/>' \
           '<Peer address="localhost"/></Peers>' in text
    assert text.endswith(",file:///user.xml")  # the user's file is read last and wins


def test_localhost_selects_loopback_unless_the_user_config_names_interfaces(tmp_path):
    # Cyclone 11 ignores a later rmw peer's announcement unless 127.0.0.1 is selected.
    loopback = '<NetworkInterface address="127.0.0.1"/>'
    text = m.discovery_config({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})
    assert f"<Interfaces>{loopback}</Interfaces>" in text
    text = m.discovery_config({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                               "ROS_STATIC_PEERS": "10.0.0.2"})
    assert f'<Interfaces><NetworkInterface autodetermine="true"/>{loopback}</Interfaces>' in text
    user_file = tmp_path / "cyclonedds.xml"
    user_file.write_text(m.loopback_config())
    for uri in (m.loopback_config(), f"file://{user_file}", f"<Tag/>, {user_file}"):
        text = m.discovery_config({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                                   "CYCLONEDDS_URI": uri})
        assert text.count("<Interfaces>") == uri.count("<Interfaces>")   # only the user's
    assert "Interfaces" not in m.discovery_config({"ROS_STATIC_PEERS": "10.0.0.2"})


def test_subnet_keeps_multicast_and_adds_static_peers():
    text = m.discovery_config({"ROS_STATIC_PEERS": "10.0.0.2"})
    assert "AllowMulticast" not in text and '<Peer address="10.0.0.2"/>' in text
    assert "localhost" not in text


def test_off_range_isolates_the_process():
    text = m.discovery_config({"ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF", "ROS_STATIC_PEERS": "10.0.0.3"})
    assert "<Tag>ros_discovery_off_" in text and "Peer" not in text


def test_unknown_range_falls_back_to_localhost_and_localhost_only_wins():
    assert m.discovery_range_from_env({"ROS_AUTOMATIC_DISCOVERY_RANGE": "moon"}) == "LOCALHOST"
    assert m.discovery_range_from_env({"ROS_LOCALHOST_ONLY": "1",
                                       "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}) == "LOCALHOST"


def test_domain_id_from_env_is_checked():
    assert m.domain_id_from_env({}) == 0
    assert m.domain_id_from_env({"ROS_DOMAIN_ID": " 42 "}) == 42
    for bad in ("abc", "-1", "300"):
        with pytest.raises(m.DiscoveryError, match="ROS_DOMAIN_ID"):
            m.domain_id_from_env({"ROS_DOMAIN_ID": bad})


@pytest.mark.parametrize("peers", ["robot.invalid", "not a host", "::1"])
def test_a_static_peer_cyclone_cannot_resolve_is_refused_instead_of_aborting(peers):
    """Cyclone DDS aborts the process (SIGABRT, no message) on such a peer."""
    with pytest.raises(m.DiscoveryError, match="ROS_STATIC_PEERS"):
        m.discovery_config({"ROS_STATIC_PEERS": peers})
