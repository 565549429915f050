"""What `arm-sim fit` reads: joint positions, velocities and applied torques, evenly sampled.

From a rosbag2 directory (MCAP or sqlite3, read with `rosbags`): `/joint_states`
(sensor_msgs/JointState), joints matched to the scene's by name (a message may carry more
joints, in any order); time is the header stamp (the bag's time where stamps are all zero).
The torque is the JointState `effort` (the node publishes the applied torque there), or,
with `torque_topic`, the latest command on `joint_torque_commands` (Float64MultiArray
[τ1, τ2]) or `joint_commands` (JointState effort by name) at or before each sample, by
bag time, zero before the first.

From a CSV: the columns `arm-sim run --csv` writes (t, q1, q2, qd1, qd2, tau1, tau2; others
ignored; a run with sensors: q1_measured ... qd2_measured in place of the truth, as
/joint_states carries them). Every problem (no such topic, names that do not match, too few, non-finite or
unevenly spaced samples) is one line: FitError.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...interface import COMMAND_TOPIC, JOINT_COMMANDS_TOPIC, JOINT_STATES_TOPIC
from ...usage import UsageError

MIN_SAMPLES = 50          # fewer cannot hold a segment, a validation segment and the noise
JITTER = 0.25             # a sample interval may differ from the median by this fraction
CSV_NEEDED = ("t", "q1", "q2", "qd1", "qd2", "tau1", "tau2")
CSV_MEASURED = ("q1_measured", "q2_measured", "qd1_measured", "qd2_measured")   # sensors
TORQUE_TOPICS = ("/" + COMMAND_TOPIC, "/" + JOINT_COMMANDS_TOPIC)


class FitError(UsageError):
    """Input `arm-sim fit` cannot use; one line on stderr, exit code 2."""


@dataclass(frozen=True)
class Recording:
    """Evenly sampled joint data: t (N,) s from the first sample; q, qd, tau (N, 2)."""

    source: str
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    tau: np.ndarray

    @property
    def dt(self) -> float:
        return float((self.t[-1] - self.t[0]) / (len(self.t) - 1))

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def __len__(self) -> int:
        return len(self.t)


def read_recording(path: str, joint_names, torque_topic: str | None = None) -> Recording:
    """The recording at `path` (a bag directory or a .csv file), checked."""
    p = Path(path)
    if not p.exists():
        raise FitError(f"{path} does not exist")
    if p.suffix.lower() == ".csv":
        if torque_topic:
            raise FitError(f"--torque-topic reads a bag; {path} is a CSV (its torque is tau1, tau2)")
        t, q, qd, tau = _read_csv(p)
    else:
        t, q, qd, tau = _read_bag(p, tuple(joint_names), torque_topic)
    return checked(path, t, q, qd, tau)


def checked(source: str, t, q, qd, tau) -> Recording:
    """A Recording of these arrays, or FitError naming the first problem."""
    t, q, qd, tau = (np.asarray(a, dtype=float) for a in (t, q, qd, tau))
    if len(t) < MIN_SAMPLES:
        raise FitError(f"{source}: {len(t)} samples; a fit needs at least {MIN_SAMPLES}")
    for name, values in (("time", t[:, None]), ("position", q), ("velocity", qd),
                         ("torque", tau)):
        bad = ~np.isfinite(values).all(axis=1)
        if bad.any():
            k = int(np.argmax(bad))
            raise FitError(f"{source}: sample {k} (t = {t[k]:.6g} s) has a non-finite {name}: "
                           f"{values[k].tolist()}")
    steps = np.diff(t)
    typical = float(np.median(steps))
    if not typical > 0:
        raise FitError(f"{source}: the samples do not advance in time")
    uneven = np.abs(steps - typical) > JITTER * typical
    if uneven.any():
        k = int(np.argmax(uneven))
        raise FitError(f"{source}: samples are not evenly spaced: {steps[k]:.6g} s between "
                       f"t = {t[k] - t[0]:.6g} s and the next, {typical:.6g} s elsewhere; "
                       "cut the recording at the gap")
    return Recording(source, t - t[0], q, qd, tau)


def _read_csv(path: Path):
    try:    # utf-8-sig: a spreadsheet's byte-order mark is not part of the first column's name
        with open(path, newline="", encoding="utf-8-sig") as stream:
            rows = list(csv.reader(stream))
    except (OSError, UnicodeDecodeError) as error:
        raise FitError(f"cannot read {path}: {getattr(error, 'strerror', None) or error}") from None
    header = [name.strip() for name in rows[0]] if rows else []
    missing = [c for c in CSV_NEEDED if c not in header]
    if missing:
        raise FitError(f"{path}: no column {', '.join(missing)}; a fit reads "
                       f"{', '.join(CSV_NEEDED)} (as `arm-sim run --csv` writes them)")
    index = [header.index(c) for c in CSV_NEEDED]
    if all(c in header for c in CSV_MEASURED):      # made with sensors: what they read
        index[1:5] = [header.index(c) for c in CSV_MEASURED]
    try:
        data = np.array([[float(row[i]) for i in index] for row in rows[1:]], dtype=float)
    except (ValueError, IndexError):
        raise FitError(f"{path}: a row is not {len(header)} numbers") from None
    data = data.reshape(-1, len(CSV_NEEDED))
    return data[:, 0], data[:, 1:3], data[:, 3:5], data[:, 5:7]


def _brief(error: Exception, limit: int = 100) -> str:
    """rosbags' message on one line, cut at `limit` characters: a damaged message
    definition is quoted whole, over many lines."""
    line = " ".join(str(error).split())
    return (line[:limit] + " ...") if len(line) > limit else (line or "no detail")


def _read_bag(path: Path, joints: tuple, torque_topic: str | None):
    from rosbags.highlevel import AnyReader, AnyReaderError

    if path.is_dir() and not (path / "metadata.yaml").exists():
        raise FitError(f"cannot read bag {path}: it holds no metadata.yaml (a rosbag2 "
                       "directory does; `ros2 bag reindex` writes one)")
    wanted = None if torque_topic is None else "/" + torque_topic.lstrip("/")
    if wanted is not None and wanted not in TORQUE_TOPICS:
        raise FitError(f"--torque-topic {torque_topic}: one of {', '.join(TORQUE_TOPICS)}")
    try:
        with AnyReader([path]) as bag:
            topics = {c.topic: c for c in bag.connections}
            states = [c for c in bag.connections if c.topic == "/" + JOINT_STATES_TOPIC]
            if not states:
                raise FitError(f"{path}: no /{JOINT_STATES_TOPIC} topic (it has "
                               f"{', '.join(sorted(topics)) or 'none'})")
            if wanted is not None and wanted not in topics:
                raise FitError(f"{path}: no {wanted} topic for --torque-topic (it has "
                               f"{', '.join(sorted(topics))})")
            samples = [_state(bag.deserialize(raw, c.msgtype), joints, log_time, wanted is None)
                       for c, log_time, raw in bag.messages(connections=states)]
            commands = [] if wanted is None else [
                (log_time, _command(bag.deserialize(raw, c.msgtype), joints))
                for c, log_time, raw in bag.messages(connections=[topics[wanted]])]
    except FitError:
        raise
    except OSError as error:
        raise FitError(f"cannot read bag {path}: {error.strerror or error}") from None
    except AnyReaderError as error:
        raise FitError(f"cannot read bag {path}: {_brief(error)}") from None
    except Exception as error:  # noqa: BLE001 - corrupt bytes fail in a dozen ways in rosbags
        raise FitError(f"cannot read bag {path}: it is damaged ({type(error).__name__}: "
                       f"{_brief(error)})") from None
    if not samples:
        raise FitError(f"{path}: /{JOINT_STATES_TOPIC} holds no message")
    stamps = np.array([s[0] for s in samples], dtype=np.int64)
    logged = np.array([s[1] for s in samples], dtype=np.int64)
    clock = logged if wanted is not None or not stamps.any() else stamps
    q, qd, tau = (np.array([s[k] for s in samples]) for k in (2, 3, 4))
    if wanted is not None:
        tau = held(commands, logged)
    order = np.argsort(clock, kind="stable")
    return clock[order] * 1e-9, q[order], qd[order], tau[order]


def _state(message, joints, log_time, need_effort):
    """(stamp ns, log ns, q, qd, tau) of one JointState, joints picked by name."""
    names = list(message.name)
    missing = [j for j in joints if j not in names]
    if missing:
        raise FitError(f"/{JOINT_STATES_TOPIC} names {names} do not include "
                       f"{', '.join(missing)}; give the recording's names with --joint-names")
    index = [names.index(j) for j in joints]
    fields = []
    for field in ("position", "velocity") + (("effort",) if need_effort else ()):
        values = np.asarray(getattr(message, field), dtype=float)
        if len(values) != len(names):
            raise FitError(f"/{JOINT_STATES_TOPIC} carries {len(values)} {field} values for "
                           f"{len(names)} names; a fit needs {field} of every joint"
                           + ("" if field != "effort" else " (or --torque-topic)"))
        fields.append(values[index])
    stamp = message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec
    return (stamp, log_time, *fields, *(() if need_effort else (np.zeros(2),)))


def _command(message, joints):
    if hasattr(message, "data"):           # Float64MultiArray: [τ1, τ2]
        if len(message.data) != 2:
            raise FitError(f"a /{COMMAND_TOPIC} message holds {len(message.data)} values, not 2")
        return np.asarray(message.data, dtype=float)
    names, effort = list(message.name), np.asarray(message.effort, dtype=float)
    if any(j not in names for j in joints) or len(effort) != len(names):
        raise FitError(f"a /{JOINT_COMMANDS_TOPIC} message names {names} with "
                       f"{len(effort)} efforts; a fit needs the effort of {', '.join(joints)}")
    return effort[[names.index(j) for j in joints]]


def held(commands, times) -> np.ndarray:
    """The latest command at or before each time (zero before the first), as the node holds it."""
    if not commands:
        return np.zeros((len(times), 2))
    commands.sort(key=lambda c: c[0])
    at = np.array([c[0] for c in commands], dtype=np.int64)
    values = np.vstack([np.zeros(2)] + [c[1] for c in commands])
    return values[np.searchsorted(at, times, side="right")]
