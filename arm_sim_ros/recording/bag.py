"""rosbag2 recordings of the arm's topics, written with the `rosbags` library.

The bags are what Jazzy's `ros2 bag record` writes, so `ros2 bag play` / `ros2 bag info`
and any MCAP tool read them: a directory holding `metadata.yaml` (rosbag2 format
version 9) and one MCAP file (`ros2` profile, CDR messages, each type's full message
definition embedded as its schema). Each topic carries the QoS profile its publishers
offered, written as Jazzy writes what the ROS graph reports for a publisher: the
policies that matter for matching, with history "unknown" and depth 0 (DDS discovery
does not carry them) and infinite durations as {sec: 9223372036, nsec: 854775807}.

`arm-sim run ... --bag DIR` (tools/run_bag.py) and the dds recorder `arm-sim record`
(tools/record.py) both write through `BagWriter`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness, QosReliability,
                                QosTime)
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.typesys import Stores, get_typestore

from ..interface import (DIAGNOSTIC_ARRAY, FLOAT64_MULTI_ARRAY, JOINT_NAMES, JOINT_STATE, NODE_NAME,
                         OK, split_stamp)
from ..usage import UsageError

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
BAG_VERSION = 9  # the rosbag2 metadata version Jazzy writes


# rmw's RMW_DURATION_INFINITE as rosbag2 writes it.
INFINITE = QosTime(9223372036, 854775807)
RELIABILITY = {"reliable": QosReliability.RELIABLE, "best_effort": QosReliability.BEST_EFFORT}
DURABILITY = {"volatile": QosDurability.VOLATILE, "transient_local": QosDurability.TRANSIENT_LOCAL}


def offered_qos(reliability: str = "reliable", durability: str = "volatile",
                deadline: QosTime = INFINITE, lifespan: QosTime = INFINITE,
                liveliness: QosLiveliness = QosLiveliness.AUTOMATIC,
                lease: QosTime = INFINITE) -> Qos:
    """A publisher's offer as the ROS graph reports it (no history: discovery lacks it)."""
    return Qos(QosHistory.UNKNOWN, 0, RELIABILITY[reliability], DURABILITY[durability],
               deadline, lifespan, liveliness, lease, False)


# The node publishes with the ROS default profile: reliable, volatile (keep-last 10).
NODE_QOS = offered_qos()


class BagError(UsageError):
    """A bag that cannot be written; one line on stderr and exit code 2, like bad usage."""


# --- messages (rosbags' Jazzy classes) -----------------------------------------------------

def _msg(msgtype: str):
    return TYPESTORE.types[msgtype]


def stamp(nanoseconds: int):
    sec, nanosec = split_stamp(nanoseconds)
    return _msg("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec)


def header(nanoseconds: int, frame_id: str = ""):
    return _msg("std_msgs/msg/Header")(stamp=stamp(nanoseconds), frame_id=frame_id)


def joint_state(nanoseconds: int, q, qd, tau, names=JOINT_NAMES,
                frame_id: str = ""):
    """JointState as the node publishes it: effort is the applied torque."""
    return _msg(JOINT_STATE)(header=header(nanoseconds, frame_id), name=list(names),
                             position=np.array(q, dtype=np.float64),
                             velocity=np.array(qd, dtype=np.float64),
                             effort=np.array(tau, dtype=np.float64))


def torque_command(tau):
    """[tau1, tau2] with an empty layout, the shape ros2_control effort controllers take."""
    layout = _msg("std_msgs/msg/MultiArrayLayout")(dim=[], data_offset=0)
    return _msg(FLOAT64_MULTI_ARRAY)(layout=layout, data=np.array(tau, dtype=np.float64))


def diagnostic_array(nanoseconds: int, message: str, values: list, level: int = OK):
    """The node's one DiagnosticStatus, `values` as [(key, text)]."""
    key_value = _msg("diagnostic_msgs/msg/KeyValue")
    status = _msg("diagnostic_msgs/msg/DiagnosticStatus")(
        level=level, name=f"{NODE_NAME}: simulation", message=message, hardware_id=NODE_NAME,
        values=[key_value(key=k, value=v) for k, v in values])
    return _msg(DIAGNOSTIC_ARRAY)(header=header(nanoseconds), status=[status])


# Element types whose rosbags sequences are numpy arrays of this dtype (others: same name).
NUMPY_DTYPES = {"byte": np.uint8, "char": np.uint8, "bool": np.bool_}
NAME, ARRAY, SEQUENCE = 2, 3, 4  # rosbags' Nodetype values in TYPESTORE.fielddefs


def message_from(msgtype: str, value):
    """The rosbags message `msgtype` holding the fields of any object with the same field
    names (a cyclonedds sample off the wire, say), nested types included."""
    _, fields = TYPESTORE.fielddefs[msgtype]
    return _msg(msgtype)(**{name: _field_from(kind, getattr(value, name))
                            for name, kind in fields})


def _field_from(kind, value):
    node, detail = kind
    if node == NAME:
        return message_from(detail, value)
    if node in (ARRAY, SEQUENCE):
        (element_node, element), _ = detail
        if element_node == NAME:
            return [message_from(element, v) for v in value]
        if element[0] == "string":
            return list(value)
        return np.array(value, dtype=NUMPY_DTYPES.get(element[0], element[0]))
    return value


# --- the writer ------------------------------------------------------------------------------

class BagWriter:
    """One rosbag2 directory being written; `close()` (or leaving the `with`) finishes it.

    Until closed the MCAP file lacks its index and metadata.yaml is absent, so every way
    out of a recording must pass through close().
    """

    def __init__(self, path):
        path = Path(path)
        if path.exists():
            raise BagError(f"{path} exists already; a recording never overwrites one, "
                           "name a new directory")
        self.path = path
        self._writer = Writer(path, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        try:
            self._writer.open()
        except (OSError, WriterError) as error:
            raise BagError(f"cannot create bag {path}: {getattr(error, 'strerror', None) or error}") \
                from None
        self._connections = {}
        self.counts: dict[str, int] = {}

    def add_topic(self, topic: str, msgtype: str, offers=(NODE_QOS,)) -> None:
        self._connections[topic] = self._writer.add_connection(
            topic, msgtype, typestore=TYPESTORE, offered_qos_profiles=list(offers))
        self.counts[topic] = 0

    def __contains__(self, topic: str) -> bool:
        return topic in self._connections

    def write(self, topic: str, nanoseconds: int, message) -> None:
        """Serialise a rosbags message with the Jazzy typestore and store it at `nanoseconds`."""
        data = TYPESTORE.serialize_cdr(message, message.__msgtype__)
        self._writer.write(self._connections[topic], nanoseconds, data)
        self.counts[topic] += 1

    def close(self) -> None:
        if self._writer.storage is not None:
            self._writer.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
