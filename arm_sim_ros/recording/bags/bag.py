"""rosbag2 recordings of the arm's topics, written with the `rosbags` library.

The bags are what Jazzy's `ros2 bag record` writes, so `ros2 bag play` / `ros2 bag info`
and any MCAP tool read them: a directory holding `metadata.yaml` (rosbag2 format
version 9) and one MCAP file (`ros2` profile, CDR messages, each type's full message
definition embedded as its schema). Each topic carries the QoS profile its publishers
offered, written as Jazzy writes what the ROS graph reports for a publisher: the
policies that matter for matching, with history "unknown" and depth 0 (DDS discovery
does not carry them) and infinite durations as {sec: 9223372036, nsec: 854775807}.

`arm-sim run ... --bag DIR` (tools/run/bag.py) and the dds recorder `arm-sim record`
(tools/wire/record.py) both write through `BagWriter`.
"""
from __future__ import annotations

import shutil
from contextlib import suppress
from pathlib import Path

import numpy as np
import yaml
from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness, QosReliability,
                                QosTime)
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.rosbag2.metadata import dump_qos_v9
from rosbags.typesys import Stores, get_typestore

from ...interface import (DIAGNOSTIC_ARRAY, FLOAT64_MULTI_ARRAY, JOINT_NAMES, JOINT_STATE,
                          NODE_NAME, OK, split_stamp)
from ...usage import UsageError
from ..csv_file import let_writes_fail_on_file_size_limit
from .mcap_file import DurableMcap

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


ROS_DISTRO = "jazzy"   # the distro whose message definitions and bag format these are (`ros2 bag info`)


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

YAML_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


class BagWriter:
    """One rosbag2 directory being written; `close()` (or leaving the `with`) finishes it.

    The bag opens in any rosbag2 reader at every moment: the MCAP file is complete after
    each chunk (DurableMcap), and metadata.yaml, written from the start and replaced after
    each chunk, describes what the file holds. A kill -9 loses at most the messages of the
    last CHUNK_SECONDS (one chunk). A write the disk refuses closes the bag with every
    chunk that fit and raises BagError (one line).
    """

    def __init__(self, path, start_ns: int = 0):
        let_writes_fail_on_file_size_limit()
        path = Path(path)
        if path.exists():
            raise BagError(f"{path} exists already; a recording never overwrites one, "
                           "name a new directory")
        self.path = path
        self.start_ns = start_ns      # the starting_time of a bag that stays empty
        self.counts: dict[str, int] = {}
        self.failed = None
        self._connections = {}
        self._writer = Writer(path, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        self._writer.STORAGE_PLUGINS = {StoragePlugin.MCAP: DurableMcap}
        try:
            self._writer.open()
            self._storage = self._writer.storage
            self._save()
        except (OSError, WriterError) as error:
            if self._writer.storage is not None:
                self._writer.storage.bio.close()
            shutil.rmtree(path, ignore_errors=True)
            raise BagError(f"cannot create bag {path}: "
                           f"{getattr(error, 'strerror', None) or error}") from None

    def add_topic(self, topic: str, msgtype: str, offers=(NODE_QOS,)) -> None:
        self._connections[topic] = self._writer.add_connection(
            topic, msgtype, typestore=TYPESTORE, offered_qos_profiles=list(offers))
        self.counts[topic] = 0
        try:       # listed at once: if the disk fills before its first chunk, readers know it
            self._save()
        except OSError as error:
            self._fail(error)

    def __contains__(self, topic: str) -> bool:
        return topic in self._connections

    def write(self, topic: str, nanoseconds: int, message) -> None:
        """Serialise a rosbags message with the Jazzy typestore and store it at `nanoseconds`."""
        if self.failed:
            raise BagError(self.failed)
        data = TYPESTORE.serialize_cdr(message, message.__msgtype__)
        try:
            self._writer.write(self._connections[topic], nanoseconds, data)
            self.counts[topic] += 1
            self._keep_up()
        except OSError as error:
            self._fail(error)

    def checkpoint(self) -> None:
        """Write a chunk that has waited CHUNK_SECONDS even when no message follows it."""
        if self._writer.storage is not None:
            try:
                self._keep_up()
            except OSError as error:
                self._fail(error)

    def _keep_up(self) -> None:
        if self._storage.due():
            self._storage.close_chunk(force=True)
        if self._storage.puts != self._described:   # a chunk went to disk: say so
            self._save()

    def close(self) -> None:
        if self._writer.storage is None:    # closed already, or failed (and closed)
            return
        try:
            self._storage.close_chunk(force=True)
            self._save(final=True)
        except OSError as error:
            self._fail(error)
        self._storage.bio.close()
        self._writer.storage = None

    def _save(self, final: bool = False, full_disk: bool = False) -> None:
        """metadata.yaml (and at the end the MCAP's copy of it) as the file now holds;
        replaced whole, so a reader never sees half of one. On a `full_disk` with no room
        for a second copy, the old one makes room for the new (and is put back if the new
        one does not fit either)."""
        info = self._metadata()
        self._storage.metadata_text = yaml.dump(info, Dumper=YAML_DUMPER,
                                                default_flow_style=False).strip()
        if final:
            self._storage.put(b"")
        text = yaml.dump({"rosbag2_bagfile_information": info}, Dumper=YAML_DUMPER,
                         default_flow_style=False)
        path, partial = self.path / "metadata.yaml", self.path / "metadata.partial.yaml"
        try:
            partial.write_text(text, "utf8")
            partial.replace(path)
        except OSError:
            partial.unlink(missing_ok=True)
            if not (full_disk and path.exists()):
                raise
            old = path.read_bytes()
            try:
                path.write_text(text, "utf8")
            except OSError:
                path.write_bytes(old)
                raise
        self._described = self._storage.puts

    def _metadata(self) -> dict:
        storage = self._storage
        count = sum(storage.on_disk.values())
        first, last = storage.span
        start, duration = (first, last - first) if count else (self.start_ns, 0)
        name = storage.path.name
        topics = [{"topic_metadata": {"name": c.topic, "type": c.msgtype,
                                      "serialization_format": c.ext.serialization_format,
                                      "offered_qos_profiles": dump_qos_v9(c.ext.offered_qos_profiles),
                                      "type_description_hash": c.digest},
                   "message_count": storage.on_disk.get(c.id, 0)}
                  for c in self._writer.connections]
        def span():   # a new dict each time: no YAML anchors and aliases
            return {"starting_time": {"nanoseconds_since_epoch": start},
                    "duration": {"nanoseconds": duration}}
        return {"version": BAG_VERSION, "storage_identifier": "mcap", "relative_file_paths": [name],
                **span(), "message_count": count, "topics_with_message_count": topics,
                "compression_format": "", "compression_mode": "",
                "files": [{"path": name, **span(), "message_count": count}],
                "custom_data": None, "ros_distro": ROS_DISTRO}

    def _fail(self, error: OSError):
        """The disk refused a write: close with what is in the file, then say so."""
        kept = sum(self._storage.on_disk.values())
        with suppress(OSError):
            self._save(full_disk=True)
        with suppress(OSError):
            self._storage.bio.close()
        self._writer.storage = None
        first, last = self._storage.span
        until = f" (spanning {(last - first) / 1e9:.3f} s)" if kept else ""
        self.failed = (f"cannot write bag {self.path}: {error.strerror or error}; the bag is "
                       f"closed and holds the {kept} messages that fit{until}")
        raise BagError(self.failed) from None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
