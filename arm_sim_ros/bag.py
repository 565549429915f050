"""rosbag2 recordings of the arm's topics, written with the `rosbags` library.

The bags are what Jazzy's `ros2 bag record` writes, so `ros2 bag play` / `ros2 bag info`
and any MCAP tool read them: a directory holding `metadata.yaml` (rosbag2 format
version 9) and one MCAP file (`ros2` profile, CDR messages, each type's full message
definition embedded as its schema). Each topic carries the QoS profile its publishers
offered, written as Jazzy writes what the ROS graph reports for a publisher: the
policies that matter for matching, with history "unknown" and depth 0 (DDS discovery
does not carry them) and infinite durations as {sec: 9223372036, nsec: 854775807}.

`arm-sim run ... --bag DIR` records an offline run here (`RunBag`); the dds recorder,
`arm-sim record`, lives in `record.py` and writes through the same `BagWriter`.
"""
from __future__ import annotations

from math import ceil, isfinite
from pathlib import Path
from time import perf_counter

import numpy as np
from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness, QosReliability,
                                QosTime)
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.typesys import Stores, get_typestore

from .cli import UsageError, scene_from_args
from .node_core import (ERROR, NODE_NAME, OK, SPECS, ParameterRefused, _steps_per_tick,
                        diagnostic_values, split_stamp)

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
BAG_VERSION = 9  # the rosbag2 metadata version Jazzy writes

JOINT_STATE = "sensor_msgs/msg/JointState"
FLOAT64_MULTI_ARRAY = "std_msgs/msg/Float64MultiArray"
DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"
NODE_TOPICS = {"/joint_states": JOINT_STATE,
               "/joint_torque_commands": FLOAT64_MULTI_ARRAY,
               "/diagnostics": DIAGNOSTIC_ARRAY}
DIAGNOSTICS_PERIOD = 1.0  # s of simulated time, as the node's 1 Hz diagnostics timer

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


def joint_state(nanoseconds: int, q, qd, tau, names=SPECS["joint_names"].default,
                frame_id: str = SPECS["frame_id"].default):
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


# --- `arm-sim run --bag DIR` ---------------------------------------------------------------

def steps_per_publish(step_size: float, publish_rate: float) -> int:
    """Integration steps between two publications, by the node's own rule: a rate whose
    period is not a whole number of steps is refused (stamps must stay simulated time)."""
    if not (isfinite(publish_rate) and publish_rate > 0):
        raise BagError(f"--publish-rate {publish_rate} must be a positive number of Hz")
    try:
        return _steps_per_tick(publish_rate, step_size)
    except ParameterRefused as error:
        raise BagError(f"--publish-rate {error.reason}") from None


def nanoseconds(sim) -> int:
    """Simulated time in ns, from the step count (never an accumulated float)."""
    return round(sim.steps * sim.step_size * 1e9)


# Policies whose torque is a command: what the offline run applied is recorded as one.
APPLIED_COMMAND_POLICIES = ("constant", "command", "command_gravity_compensation")


class RunBag:
    """A recorder for `arm-sim run`: JointState every publish period (stamped with
    simulated time, the bag's clock too), the applied command alongside it when the
    policy takes commands, and diagnostics every simulated second (and at the end)."""

    def __init__(self, path, publish_steps: int):
        self.path = path
        self.publish_steps = publish_steps

    def start(self, sim) -> None:
        self.writer = BagWriter(self.path)
        self.commands = sim.scene.policy in APPLIED_COMMAND_POLICIES
        for topic, msgtype in NODE_TOPICS.items():
            if self.commands or topic != "/joint_torque_commands":
                self.writer.add_topic(topic, msgtype)
        self.diagnostics_steps = ceil(DIAGNOSTICS_PERIOD / sim.step_size - 1e-9)
        self.last_diagnostics = 0
        self.max_abs_residual = 0.0
        self.wall_start = perf_counter()
        self.publish(sim)

    def step(self, sim) -> None:
        if sim.steps % self.publish_steps == 0:
            self.publish(sim)
        if sim.steps - self.last_diagnostics >= self.diagnostics_steps:
            self.diagnose(sim)

    def finish(self, sim) -> None:
        try:
            if sim.steps != self.last_diagnostics:
                self.diagnose(sim)
        finally:
            self.writer.close()

    def publish(self, sim) -> None:
        s, t = sim.sample(), nanoseconds(sim)
        if not sim.holding:  # the largest |residual| at a tick, as the node keeps it
            self.max_abs_residual = max(self.max_abs_residual, abs(s.residual))
        self.writer.write("/joint_states", t, joint_state(t, s.q, s.qd, s.tau))
        if self.commands:
            self.writer.write("/joint_torque_commands", t, torque_command(applied_command(sim)))

    def diagnose(self, sim) -> None:
        """The node's diagnostics, same keys; an offline run refuses and misses nothing."""
        t, wall = nanoseconds(sim), perf_counter() - self.wall_start
        command = applied_command(sim) if self.commands else (0.0, 0.0)
        # A refused (non-finite) step leaves the last finite state in place, as in the node.
        level, message = (ERROR, sim.fault) if sim.holding else (OK, "running")
        values = diagnostic_values(sim, f"{sim.time / wall:.3f}" if wall > 0 else "inf",
                                   self.max_abs_residual, sim.holding, command, self.publish_steps)
        self.writer.write("/diagnostics", t, diagnostic_array(t, message, level=level, values=values))
        self.last_diagnostics = sim.steps


def applied_command(sim):
    """The command part of the torque: the constant torque, or the held command."""
    scene = sim.scene
    return scene.constant_torque if scene.policy == "constant" else tuple(sim.dynamics.command)


def run_recorder(args):
    """RUN_RECORDERS hook: a RunBag for `--bag DIR`, refused before the run if the rate
    does not divide the step or DIR exists."""
    steps = steps_per_publish(scene_from_args(args).step_size, args.publish_rate)
    if Path(args.bag).exists():
        raise BagError(f"--bag {args.bag} exists already; a recording never overwrites one")
    return RunBag(args.bag, steps)
