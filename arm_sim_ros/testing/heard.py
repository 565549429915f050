"""What crosses the wire in a test, heard: the states the node publishes, their truth and
the commands that answer them, each keyed by stamp, so that a trace's rows are the same
whatever order the samples arrived in (wire.WireArm listens with it)."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .trace import Trace

TOPICS = {"joint_states": "JointState", "arm_sim/true_joint_states": "JointState",
          "joint_commands": "JointState", "joint_torque_commands": "Float64MultiArray"}
DEPTH = 10_000            # samples a reader keeps: drained far more often (wire.DRAIN)


def stamp_of(message) -> int:
    return message.header.stamp.sec * 10**9 + message.header.stamp.nanosec


class Heard:
    """Readers of the node's topics on `participant`, and what they heard so far."""

    def __init__(self, participant, recording: Path | None):
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic
        from ..node.wire import messages as msg
        p = participant
        self.kinds = {topic: getattr(msg, kind) for topic, kind in TOPICS.items()}
        self.readers = {topic: DataReader(p, Topic(p, msg.ros_topic(topic), kind),
                                          qos=msg.default_qos(kind, depth=DEPTH))
                        for topic, kind in self.kinds.items()}
        self.recording = recording
        self.states, self.truth, self.answers = {}, {}, {}

    def take(self) -> None:
        """What arrived since the last look, by stamp (the first copy of each kept)."""
        for message in self._new("joint_states"):
            self.states.setdefault(stamp_of(message), message)
        for message in self._new("arm_sim/true_joint_states"):
            self.truth.setdefault(stamp_of(message), message)
        for message in self._new("joint_commands"):      # by the stamp of what it answers
            self.answers.setdefault(stamp_of(message), message)
        for message in self._new("joint_torque_commands"):   # no stamp: the latest heard
            self.answers.setdefault(max(self.states, default=0), message)

    def _new(self, topic: str) -> list:
        kind = self.kinds[topic]
        return [m for m in self.readers[topic].take(N=100_000) if isinstance(m, kind)]

    def hears(self, writer) -> bool:
        """Whether a command reader has matched `writer` (then every answer of it is heard)."""
        return any(reader_hears(self.readers[topic], writer.guid)
                   for topic in ("joint_commands", "joint_torque_commands"))

    def trace(self, scene: str, silence: float, evidence: dict) -> Trace:
        """Every state heard so far, by stamp, with its truth and the command that answered
        it; the energy books from the node's recording, read when first asked."""
        self.take()
        stamps = sorted(self.states)
        readings = [self.states[s] for s in stamps]
        truth = [self.truth.get(s, m) for s, m in zip(stamps, readings)]
        origin = stamps[0] if stamps else 0
        t = (np.array(stamps, dtype=np.int64) - origin) / 1e9
        pairs = lambda rows, field: np.array([list(getattr(m, field))[:2] for m in rows],  # noqa: E731
                                             dtype=float).reshape(-1, 2)
        # the latest state's answer, if it came, is the next run's: NaN here, as in process
        commands = np.array([command_values(self.answers.get(s)) for s in stamps[:-1]]
                            + [[np.nan, np.nan]] * bool(stamps), dtype=float).reshape(-1, 2)
        return Trace(t=t, q=pairs(truth, "position"), qd=pairs(truth, "velocity"),
                     measured_q=pairs(readings, "position"),
                     measured_qd=pairs(readings, "velocity"), command=commands,
                     tau=pairs(truth, "effort"),
                     books=RecordedBooks(self.recording, t, silence), scene=scene,
                     evidence=evidence | ({"rrd": str(self.recording)} if self.recording
                                          else {}))


def reader_hears(reader, guid) -> bool:
    """Whether `reader` has matched the writer of this GUID."""
    try:
        return any(reader.get_matched_publication_data(handle).key == guid
                   for handle in reader.get_matched_publications())
    except Exception:             # noqa: BLE001 - a match arriving meanwhile: ask again
        return False


def command_values(message) -> list:
    """[joint 1, joint 2] of an answer: its efforts, else set-points (NaN if none came)."""
    if message is None:
        return [np.nan, np.nan]
    if hasattr(message, "data"):
        return list(message.data)[:2]
    for field in ("effort", "position", "velocity"):
        values = list(getattr(message, field))
        if values:
            return values[:2]
    return [np.nan, np.nan]


class RecordedBooks(dict):
    """The energy books at the trace's times from the node's recording, read when first
    asked: after the node has written them (it writes its file every second: this waits up
    to `silence` for the last)."""

    KEYS = {"kinetic": "kinetic", "stored": "potential", "inputs": "inputs",
            "losses": "losses", "residual": "residual"}

    def __init__(self, recording: Path | None, t: np.ndarray, silence: float):
        super().__init__()
        self.recording, self.t, self.silence = recording, t, silence

    def __missing__(self, key):
        from ..recording.rrd.readback import read, table
        if self.recording is None:
            raise KeyError(f"{key}: the node writes no recording (rerun_path), where the "
                           "energy books come from")
        deadline = time.monotonic() + self.silence
        while True:
            columns = _energy_columns(table(read(self.recording)))
            if columns is not None and columns["sim_time"][-1] >= self.t[-1] - 1e-9 or \
                    time.monotonic() > deadline:
                break
            time.sleep(0.2)
        if columns is None:
            raise KeyError(f"{key}: the node's recording {self.recording} has no energy "
                           "books")
        at = np.searchsorted(columns["sim_time"], self.t - 1e-9)
        at = np.minimum(at, len(columns["sim_time"]) - 1)
        for name in self.KEYS:
            self[name] = np.asarray(columns[name])[at]
        return self[key]


def _energy_columns(recording_table) -> dict | None:
    """{sim_time, kinetic, stored, inputs, losses, residual} arrays of a recording's table
    (readback.table: books/stored/kinetic is T - T0, the other books/stored/* the stored
    energies, books/input/* and books/loss/* summed, energy/balance_residual), or None while
    it holds none."""
    header, rows = recording_table
    rows = [row for row in rows if row[header.index("sim_time [s]")] is not None]
    entity = [name.partition(":")[0] for name in header]
    if not rows or "energy/balance_residual" not in entity:
        return None
    values = np.array([[np.nan if v is None else v for v in row] for row in rows], dtype=float)

    def summed(match):
        chosen = [k for k, name in enumerate(entity) if match(name)]
        return np.nan_to_num(values[:, chosen]).sum(axis=1) if chosen else \
            np.zeros(len(values))
    kinetic = summed(lambda name: name == "books/stored/kinetic")
    return {"sim_time": values[:, 0], "kinetic": kinetic,
            "stored": summed(lambda n: n.startswith("books/stored/") and n != "books/stored/kinetic"),
            "inputs": summed(lambda n: n.startswith("books/input/")),
            "losses": summed(lambda n: n.startswith("books/loss/")),
            "residual": values[:, entity.index("energy/balance_residual")]}
