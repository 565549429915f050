"""ROS 2 Jazzy messages as cyclonedds IDL types, laid out exactly as rmw_cyclonedds puts them
on the wire, plus the QoS profiles and discovery configuration it uses.

What makes a real rclpy node on rmw_cyclonedds talk to these (see DESIGN.md, "Wire facts"):
type names `<pkg>::msg::dds_::<Type>_`, final keyless structs in XCDR1, topics `rt/<name>`,
the ROS default QoS (reliable, volatile, keep-last 10), USER_DATA `typehash=RIHS01_…;` on
endpoints and `enclave=/;` on the participant, and the same discovery settings, built here
from ROS_DOMAIN_ID / ROS_AUTOMATIC_DISCOVERY_RANGE / ROS_STATIC_PEERS / CYCLONEDDS_URI.
Messages are Python dataclasses: pass lists (not numpy arrays) to sequence fields. (No
`from __future__ import annotations` here: cyclonedds resolves the field types at runtime.)
"""

import atexit
import os
import sys
from dataclasses import dataclass, field
from xml.sax.saxutils import escape, quoteattr

from .one_cyclone import refuse_foreign_cyclone, require_cyclonedds

require_cyclonedds()        # what to install, not a ModuleNotFoundError (colcon installs)
refuse_foreign_cyclone()    # before cyclonedds loads (and binds) its C library

from cyclonedds.core import DDSException  # noqa: E402
from cyclonedds.domain import Domain, DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.annotations import final  # noqa: E402
from cyclonedds.idl.types import (array, bounded_str, float64, int32, sequence,  # noqa: E402
                                  uint8, uint32)
from cyclonedds.qos import Policy, Qos  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

from .cdr import LITTLE_ENDIAN, clock_cdr, joint_state_cdr  # noqa: E402
from .errors import (DiscoveryError, check_topic_name, cyclone_messages,
                     cyclone_reason, refused_configuration, static_peers)  # noqa: E402


# --- builtin_interfaces / rosgraph_msgs / std_msgs ---------------------------------------

@final
@dataclass
class Time(IdlStruct, typename="builtin_interfaces.msg.dds_.Time_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@final
@dataclass
class Clock(IdlStruct, typename="rosgraph_msgs.msg.dds_.Clock_"):
    clock: Time = field(default_factory=Time)     # /clock, as Gazebo publishes it

    def serialize(self, buffer=None, endianness=None, use_version_2=None) -> bytes:
        # written every tick: the generic serializer's XCDR1 bytes, one struct.pack (cdr.py)
        if buffer is None and endianness is None and not use_version_2 and LITTLE_ENDIAN:
            return clock_cdr(self.clock.sec, self.clock.nanosec)
        return super().serialize(buffer, endianness, use_version_2)


@final
@dataclass
class Header(IdlStruct, typename="std_msgs.msg.dds_.Header_"):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@final
@dataclass
class MultiArrayDimension(IdlStruct, typename="std_msgs.msg.dds_.MultiArrayDimension_"):
    label: str = ""
    size: uint32 = 0
    stride: uint32 = 0


@final
@dataclass
class MultiArrayLayout(IdlStruct, typename="std_msgs.msg.dds_.MultiArrayLayout_"):
    dim: sequence[MultiArrayDimension] = field(default_factory=list)
    data_offset: uint32 = 0


@final
@dataclass
class Float64MultiArray(IdlStruct, typename="std_msgs.msg.dds_.Float64MultiArray_"):
    layout: MultiArrayLayout = field(default_factory=MultiArrayLayout)
    data: sequence[float64] = field(default_factory=list)


# --- sensor_msgs ---------------------------------------------------------------------------

@final
@dataclass
class JointState(IdlStruct, typename="sensor_msgs.msg.dds_.JointState_"):
    header: Header = field(default_factory=Header)
    name: sequence[str] = field(default_factory=list)
    position: sequence[float64] = field(default_factory=list)
    velocity: sequence[float64] = field(default_factory=list)
    effort: sequence[float64] = field(default_factory=list)

    def serialize(self, buffer=None, endianness=None, use_version_2=None) -> bytes:
        # written every tick: the generic serializer's XCDR1 bytes, one struct.pack (cdr.py)
        if buffer is None and endianness is None and not use_version_2 and LITTLE_ENDIAN:
            return joint_state_cdr(self)
        return super().serialize(buffer, endianness, use_version_2)


# --- diagnostic_msgs -----------------------------------------------------------------------

@final
@dataclass
class KeyValue(IdlStruct, typename="diagnostic_msgs.msg.dds_.KeyValue_"):
    key: str = ""
    value: str = ""


@final
@dataclass
class DiagnosticStatus(IdlStruct, typename="diagnostic_msgs.msg.dds_.DiagnosticStatus_"):
    OK = 0      # level constants, as in DiagnosticStatus.msg (class attributes, not fields)
    WARN = 1
    ERROR = 2
    STALE = 3
    level: uint8 = 0
    name: str = ""
    message: str = ""
    hardware_id: str = ""
    values: sequence[KeyValue] = field(default_factory=list)


@final
@dataclass
class DiagnosticArray(IdlStruct, typename="diagnostic_msgs.msg.dds_.DiagnosticArray_"):
    header: Header = field(default_factory=Header)
    status: sequence[DiagnosticStatus] = field(default_factory=list)


# --- rmw_dds_common: what `ros2 node list` reads ------------------------------------------

@final
@dataclass
class Gid(IdlStruct, typename="rmw_dds_common.msg.dds_.Gid_"):
    data: array[uint8, 16] = field(default_factory=lambda: [0] * 16)


@final
@dataclass
class NodeEntitiesInfo(IdlStruct, typename="rmw_dds_common.msg.dds_.NodeEntitiesInfo_"):
    node_namespace: bounded_str[256] = "/"
    node_name: bounded_str[256] = ""
    reader_gid_seq: sequence[Gid] = field(default_factory=list)
    writer_gid_seq: sequence[Gid] = field(default_factory=list)


@final
@dataclass
class ParticipantEntitiesInfo(IdlStruct,
                              typename="rmw_dds_common.msg.dds_.ParticipantEntitiesInfo_"):
    gid: Gid = field(default_factory=Gid)
    node_entities_info_seq: sequence[NodeEntitiesInfo] = field(default_factory=list)


# ROS interface name ("pkg/msg/Type") of each wire type, for rosbags and the type hash.
ROS_TYPE_NAMES = {
    Time: "builtin_interfaces/msg/Time",
    Clock: "rosgraph_msgs/msg/Clock",
    Header: "std_msgs/msg/Header",
    MultiArrayDimension: "std_msgs/msg/MultiArrayDimension",
    MultiArrayLayout: "std_msgs/msg/MultiArrayLayout",
    Float64MultiArray: "std_msgs/msg/Float64MultiArray",
    JointState: "sensor_msgs/msg/JointState",
    KeyValue: "diagnostic_msgs/msg/KeyValue",
    DiagnosticStatus: "diagnostic_msgs/msg/DiagnosticStatus",
    DiagnosticArray: "diagnostic_msgs/msg/DiagnosticArray",
    Gid: "rmw_dds_common/msg/Gid",
    NodeEntitiesInfo: "rmw_dds_common/msg/NodeEntitiesInfo",
    ParticipantEntitiesInfo: "rmw_dds_common/msg/ParticipantEntitiesInfo",
}

# RIHS01 type hashes (REP 2011) as rosidl computes them for Jazzy; test_ros_messages checks
# each against the rosbags library, so the runtime needs no rosbags import.
TYPE_HASHES = {
    "builtin_interfaces/msg/Time":
        "RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197",
    "rosgraph_msgs/msg/Clock":
        "RIHS01_692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564",
    "std_msgs/msg/Header":
        "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01",
    "std_msgs/msg/Float64MultiArray":
        "RIHS01_1025ddc6b9552d191f89ef1a8d2f60f3d373e28b283d8891ddcc974e8c55397f",
    "sensor_msgs/msg/JointState":
        "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e",
    "diagnostic_msgs/msg/DiagnosticArray":
        "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e",
    "rmw_dds_common/msg/ParticipantEntitiesInfo":
        "RIHS01_e725f4a506958c79f95dd693b965722c57b19cd18e7eff984f49561b93dc985d",
}


def ros_topic(name: str) -> str:
    """The DDS topic rmw gives a ROS topic: `joint_states` -> `rt/joint_states`; a name rcl
    would refuse is refused here (DiscoveryError, one line), for every caller."""
    return "rt/" + check_topic_name(name, "ROS topic name").lstrip("/")


# --- QoS -----------------------------------------------------------------------------------

def _endpoint_qos(message_type, *policies) -> Qos:
    user_data = f"typehash={TYPE_HASHES[ROS_TYPE_NAMES[message_type]]};".encode()
    return Qos(*policies, Policy.Userdata(user_data))


def default_qos(message_type, depth: int = 10) -> Qos:
    """rmw_cyclonedds' mapping of the ROS default profile: reliable, volatile, keep-last 10."""
    return _endpoint_qos(message_type,
                         Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
                         Policy.Durability.Volatile,
                         Policy.History.KeepLast(depth))


def discovery_info_qos(history=Policy.History.KeepLast(1)) -> Qos:
    """`ros_discovery_info`: reliable, transient-local, keep-last 1 (late joiners see the node);
    read keep-all as rmw_cyclonedds does (keyless: every participant's update is one instance)."""
    return _endpoint_qos(ParticipantEntitiesInfo,
                         Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
                         Policy.Durability.TransientLocal, history)


PARTICIPANT_QOS = Qos(Policy.Userdata(b"enclave=/;"))


# --- discovery configuration, as rmw_cyclonedds builds it ---------------------------------

DISCOVERY_RANGES = ("SUBNET", "LOCALHOST", "OFF", "SYSTEM_DEFAULT")


def domain_id_from_env(env=None) -> int:
    text = (os.environ if env is None else env).get("ROS_DOMAIN_ID", "").strip()
    if not text:
        return 0
    try:
        value = int(text)
    except ValueError:
        raise DiscoveryError(f"ROS_DOMAIN_ID={text!r} is not an integer; set a domain id "
                             "from 0 to 232, or unset it") from None
    if not 0 <= value <= 232:
        raise DiscoveryError(f"ROS_DOMAIN_ID={value} is outside 0..232; set a domain id "
                             "from 0 to 232, or unset it")
    return value


def discovery_range_from_env(env=None) -> str:
    """Jazzy's rules: unset means SUBNET, ROS_LOCALHOST_ONLY=1 forces LOCALHOST, and an
    unknown value falls back to LOCALHOST (rcl warns and does the same)."""
    env = os.environ if env is None else env
    if env.get("ROS_LOCALHOST_ONLY", "") == "1":
        return "LOCALHOST"
    text = env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").strip()
    if not text:
        return "SUBNET"
    return text if text in DISCOVERY_RANGES else "LOCALHOST"


def discovery_config(env=None) -> str:
    """Cyclone configuration for this process, built as rmw_cyclonedds' check_create_domain
    builds it: a discovery fragment, then CYCLONEDDS_URI (later fragments override).
    One addition: on LOCALHOST it selects the loopback interface (with the default one when
    there are static peers), unless CYCLONEDDS_URI selects interfaces itself (Cyclone refuses
    one selected twice).
    rmw peers announce themselves to 127.0.0.1, and Cyclone 11 ignores discovery arriving on
    an interface it has not selected: a ROS node started after ours would never find it."""
    env = os.environ if env is None else env
    scope = discovery_range_from_env(env)
    text = env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").strip()
    if text and text not in DISCOVERY_RANGES:   # rmw warns and uses LOCALHOST: say it instead
        raise DiscoveryError(f"ROS_AUTOMATIC_DISCOVERY_RANGE={text!r} is not one of "
                             f"{', '.join(DISCOVERY_RANGES)}; set one of them or unset it")
    peers = static_peers(env)
    user_uri = env.get("CYCLONEDDS_URI", "")
    add_localhost = scope == "LOCALHOST"
    add_peers = scope in ("SUBNET", "LOCALHOST")
    no_multicast = scope in ("LOCALHOST", "OFF")
    fragment = ""
    if add_localhost or (add_peers and peers) or no_multicast:
        fragment = "<CycloneDDS><Domain>"
        general = ""
        if add_localhost and not _selects_interfaces(user_uri):
            # Static peers are other hosts: the default interface reaches them.
            default = '<NetworkInterface autodetermine="true"/>' if peers else ""
            general += (f'<Interfaces>{default}<NetworkInterface address="127.0.0.1"/>'
                        "</Interfaces>")
        if no_multicast:
            general += "<AllowMulticast>false</AllowMulticast>"
        if general:
            fragment += f"<General>{general}</General>"
        if scope == "OFF":
            # Only a participant with this exact tag (this pid) could discover us.
            fragment += (f"<Discovery><ParticipantIndex>none</ParticipantIndex>"
                         f"<Tag>ros_discovery_off_{os.getpid()}</Tag>")
        else:
            fragment += ("<Discovery><ParticipantIndex>auto</ParticipantIndex>"
                         "<MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>")
        listed = (["localhost"] if add_localhost else []) + (peers if add_peers else [])
        if listed:
            fragment += ("<Peers>" + "".join(f"<Peer address={quoteattr(p)}/>" for p in listed)
                         + "</Peers>")
        fragment += "</Discovery></Domain></CycloneDDS>,"
    return fragment + user_uri


def _selects_interfaces(uri: str) -> bool:
    """Whether a CYCLONEDDS_URI (XML fragments and/or files, comma-separated) names interfaces."""
    for part in filter(None, (p.strip() for p in uri.split(","))):
        if not part.startswith("<"):
            try:
                with open(part.removeprefix("file://")) as stream:
                    part = stream.read()
            except OSError:
                continue          # Cyclone itself reports a file it cannot read
        if "NetworkInterface" in part:
            return True
    return False


def loopback_config(tag: str = "") -> str:
    """Loopback only, for tests and benchmarks: never leaves the machine, never meets the LAN.
    With a `tag`, only participants configured with the same tag meet, so concurrent test runs
    on one machine (same domain ids) cannot see each other."""
    return ("<CycloneDDS><Domain><General><Interfaces>"
            "<NetworkInterface address=\"127.0.0.1\"/></Interfaces>"
            "<AllowMulticast>false</AllowMulticast></General>"
            "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
            "<MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>"
            "<Peers><Peer address=\"127.0.0.1\"/></Peers>"
            + (f"<Tag>{escape(tag)}</Tag>" if tag else "")
            + "</Discovery></Domain></CycloneDDS>")


LOOPBACK_CONFIG = loopback_config()

_configured_domains: dict[int, Domain] = {}


@atexit.register
def close_domains() -> None:
    """Delete the domains this process configured, and with each whatever is left in it,
    while the interpreter is whole (at exit, or when a node has closed). Left to interpreter
    teardown, each Domain went in arbitrary order among the entities, Cyclone's threads and
    its Python type support: the suspect of two heap corruptions after green test runs."""
    while _configured_domains:
        _configured_domains.popitem()[1].__del__()


def make_participant(domain_id: int | None = None, config: str | None = None,
                     env=None) -> DomainParticipant:
    """A participant configured the way rmw_cyclonedds would configure it from `env`
    (default os.environ), or with an explicit Cyclone `config` (e.g. LOOPBACK_CONFIG).

    Cyclone reads a domain's configuration once, when the first participant in it is created;
    the Domain object is kept here so later participants in this process share it.
    """
    if domain_id is None:
        domain_id = domain_id_from_env(env)
    text = discovery_config(env) if config is None else config   # refuses a bad environment
    with cyclone_messages() as printed:
        try:
            if domain_id not in _configured_domains:
                _configured_domains[domain_id] = Domain(domain_id, text or None)
            participant = DomainParticipant(domain_id, qos=PARTICIPANT_QOS)
        except DDSException:
            failed = True
        else:
            failed = False
    if failed:   # Cyclone's reason in one line, instead of its stderr lines and a traceback
        uri = (os.environ if env is None else env).get("CYCLONEDDS_URI", "")
        raise refused_configuration(uri, config is not None, cyclone_reason(printed[0]))
    if printed[0]:
        sys.stderr.write(printed[0])   # warnings of a configuration that works: shown as given
    return participant


def matched(endpoint) -> int:
    """How many remote endpoints a writer or reader is matched with. cyclonedds-python
    11.0.1 raises IndexError when a match arrives between its count and its copy: ask again."""
    get = getattr(endpoint, "get_matched_subscriptions", None) or endpoint.get_matched_publications
    for _ in range(100):
        try:
            return len(get())
        except IndexError:
            continue
    return 0


def gid(entity) -> Gid:
    """rmw's gid of a DDS entity: its 16-byte GUID."""
    return Gid(data=list(entity.guid.bytes))
