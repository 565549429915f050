"""A controller under test over the wire: the node in a subprocess on a private
ROS_DOMAIN_ID, on loopback, in lockstep; the controller is any node on that domain (rclpy,
rclcpp, or Controller below, on this package's dds transport).

    arm = WireArm("release")                   # started, found, paused, in lockstep
    with Controller(pd, arm):                   # answers each state it reads
        trace = arm.run(2.0)                    # 2 s: one tick per answered state
    arm.close()

Lockstep is ordered by the messages (schedule.Lockstep): each JointState the node publishes
awaits the command that answers it, a JointState on joint_commands carrying that state's
stamp in its header; the node ticks when, and only when, that answer has come. `run(seconds)`
asks the node (paused) for that many ticks (StepSimulation), each still waiting for its
answer, and returns when they are done: so the same controller gives the same trace, bit for
bit, however loaded the machine. A wall-clock limit (`silence`) only ever reports a
controller that went silent, naming the state it left unanswered.
"""
from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from ..interface import split_stamp
from .loop import Reading, ControllerError
from .trace import Trace

DOMAINS = range(80, 120)          # private domains: the project's own tests use others
START_TIMEOUT = 120.0             # s: a first run compiles the scene's kernels (tens of s)
SILENCE = 10.0                    # s of wall time without a new state: the controller is gone
DRAIN = 0.02                      # s between two looks at the states while a run goes on
_taken = itertools.count()


def private_domain() -> int:
    """A domain id from DOMAINS this process has not used yet, apart from pytest-xdist's
    other workers' (ARM_SIM_TEST_DOMAIN chooses one)."""
    chosen = os.environ.get("ARM_SIM_TEST_DOMAIN")
    if chosen:
        return int(chosen)
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:]
    offset = int(worker) * 10 if worker.isdigit() else os.getpid() % len(DOMAINS)
    return DOMAINS[(offset + next(_taken)) % len(DOMAINS)]


def wire_env(domain_id: int, env=None) -> dict:
    """The environment a node on this domain runs in: loopback discovery, as a ROS 2 peer's."""
    env = dict(os.environ if env is None else env)
    env.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.pop("ROS_STATIC_PEERS", None)
    return env


def stamp_of(message) -> int:
    return message.header.stamp.sec * 10**9 + message.header.stamp.nanosec


class WireArm:
    """The node in lockstep in a subprocess (or one a launch started: attach), and what
    crosses the wire as a trace."""

    def __init__(self, scene: str = "release", parameters: dict | None = None, *,
                 transport: str = "dds", directory=None, domain_id: int | None = None,
                 silence: float = SILENCE, name: str = "arm_sim"):
        domain_id = private_domain() if domain_id is None else domain_id
        directory = Path(directory or ".")
        stem = next(f"{name}{n or ''}" for n in itertools.count()      # never replace one
                    if not (directory / f"{name}{n or ''}.rrd").exists())
        values = lockstep_parameters(scene, parameters) | {
            "rerun_path": str(directory / f"{stem}.rrd")}
        # the fixture's participant first: the node's first state then has a reader
        self._connect(domain_id, wire_env(domain_id), values, silence)
        self.log_path = directory / f"{stem}.log"
        self.log = open(self.log_path, "wb")
        command = [sys.executable, "-m", "arm_sim_ros.node.main", "--transport", transport,
                   "--quiet", "--ros-args",
                   *itertools.chain.from_iterable(("-p", f"{k}:={ros_value(v)}")
                                                  for k, v in values.items())]
        self.process = subprocess.Popen(command, env=self.env, stdout=self.log,
                                        stderr=subprocess.STDOUT)
        self._wait_for_node()

    @classmethod
    def attach(cls, parameters: dict | None = None, *, domain_id: int | None = None,
               silence: float = SILENCE) -> "WireArm":
        """The node a launch started (testing/launch.py) on this process's ROS_DOMAIN_ID
        (or `domain_id`), with the `parameters` it was given (publish_rate, scene,
        rerun_path: the energy books come from its recording, if it writes one)."""
        from ..node.wire import messages as msg
        arm = cls.__new__(cls)
        domain_id = msg.domain_id_from_env() if domain_id is None else domain_id
        arm._connect(domain_id, dict(os.environ), lockstep_parameters(
            (parameters or {}).get("scene", "release"), parameters), silence)
        arm.process, arm.log, arm.log_path = None, None, "the launch's output"
        arm._wait_for_node()
        return arm

    def _connect(self, domain_id: int, env: dict, values: dict, silence: float) -> None:
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic
        from ..node.wire import messages as msg
        from ..tools.wire.sim_client import SimulationClient

        self.domain_id, self.env, self.silence = domain_id, env, silence
        self.scene, self.publish_rate = values["scene"], float(values.get("publish_rate", 100.0))
        self.recording = Path(values["rerun_path"]) if values.get("rerun_path") else None
        self.client = SimulationClient(domain_id, msg.discovery_config(env))
        p = self.client.participant
        deep = lambda t: msg.default_qos(t, depth=10_000)  # noqa: E731 (drained every DRAIN)
        self.readers = {topic: DataReader(p, Topic(p, msg.ros_topic(topic), kind),
                                          qos=deep(kind))
                        for topic, kind in (("joint_states", msg.JointState),
                                            ("arm_sim/true_joint_states", msg.JointState),
                                            ("joint_commands", msg.JointState),
                                            ("joint_torque_commands", msg.Float64MultiArray))}
        self.states, self.truth, self.answers = {}, {}, {}
        self._replied = WaitSet(p)
        self._replied.attach(ReadCondition(self.client.services["step_simulation"].reader,
                                           SampleState.Any | ViewState.Any | InstanceState.Any))

    # -- running ----------------------------------------------------------------------------

    def run(self, seconds: float) -> Trace:
        """`seconds` more of simulated time, one tick per answered state; the trace of the
        whole run so far."""
        from cyclonedds.util import duration
        ticks = round(seconds * self.publish_rate)
        last = max(self.states)
        reply = self.client.services["step_simulation"].ask(steps=ticks)
        seen, quiet_since = len(self.states), time.monotonic()
        # Blocked on the reply, the states waiting in the readers (no work of ours a tick):
        # a look at them now and then tells a loop that goes on from one gone silent.
        while (answer := reply()) is None:
            self._replied.wait(duration(seconds=DRAIN))
            self._take()
            if len(self.states) != seen:
                seen, quiet_since = len(self.states), time.monotonic()
            elif time.monotonic() - quiet_since > self.silence:
                self._alive()
                raise ControllerError(self._silent(), self.trace())
        if answer.result.result != 1:
            raise ControllerError(f"the node refused to step: {answer.result.error_message}",
                                  self.trace())
        end = last + ticks * round(1e9 / self.publish_rate)
        deadline = time.monotonic() + self.silence
        while max(self.states, default=-1) < end and time.monotonic() < deadline:
            self._take()                  # the last states are on their way
            time.sleep(0.0002)
        return self.trace()

    def _first_state(self, deadline: float) -> bool:
        """Until the state the node awaits an answer to at start is here (it comes once this
        reader has matched: every trace starts at that state), or `deadline`."""
        while not self.states and time.monotonic() < deadline:
            self._alive()
            time.sleep(DRAIN)
            self._take()
        return bool(self.states)

    def wait_for_writer(self, writer) -> None:
        """Until this trace's command reader has matched `writer` (a controller in this
        process: its answers are then all heard, the first too)."""
        from ..node.wire import messages as msg
        deadline = time.monotonic() + self.silence
        guid = writer.guid
        while not any(reader_hears(self.readers[topic], guid)
                      for topic in ("joint_commands", "joint_torque_commands")):
            if time.monotonic() > deadline:
                raise TimeoutError(f"the trace did not hear the controller's writer on domain "
                                   f"{self.domain_id} within {self.silence:g} s")
            time.sleep(0.001)
        del msg

    def _silent(self) -> str:
        t = f"t = {(max(self.states) - min(self.states)) / 1e9:.6f} s"
        return (f"no command answered the state at {t} within {self.silence:g} s (wall): the "
                f"controller went silent, or answers without the state's stamp in its "
                f"header; domain {self.domain_id}, node log {self.log_path}")

    def _take(self) -> None:
        for message in self._new("joint_states"):
            self.states.setdefault(stamp_of(message), message)
        for message in self._new("arm_sim/true_joint_states"):
            self.truth.setdefault(stamp_of(message), message)
        for message in self._new("joint_commands"):      # by the stamp of what it answers
            self.answers.setdefault(stamp_of(message), message)
        for message in self._new("joint_torque_commands"):   # no stamp: the latest heard
            self.answers.setdefault(max(self.states, default=0), message)

    def _new(self, topic: str) -> list:
        from ..node.wire import messages as msg
        kind = msg.Float64MultiArray if topic == "joint_torque_commands" else msg.JointState
        return [m for m in self.readers[topic].take(N=100_000) if isinstance(m, kind)]

    # -- the trace --------------------------------------------------------------------------

    def trace(self) -> Trace:
        """Every state published so far, by stamp, with its truth and the command that
        answered it; the energy books from the node's recording, read when first asked."""
        self._take()
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
                     tau=pairs(truth, "effort"), books=RecordedBooks(self, t),
                     scene=self.scene, evidence={"log": str(self.log_path)} | (
                         {"rrd": str(self.recording)} if self.recording else {}))

    # -- starting and stopping --------------------------------------------------------------

    def _wait_for_node(self) -> None:
        """Until the node's services and topics are matched and its first state is here."""
        deadline = time.monotonic() + START_TIMEOUT
        while True:
            self._alive()
            try:
                self.client.wait_for_node()
                break
            except TimeoutError:
                if time.monotonic() > deadline:
                    break
        if not self._first_state(deadline):
            self.close()
            raise TimeoutError(f"the node did not come up on domain {self.domain_id} within "
                               f"{START_TIMEOUT:g} s; its log: {self.log_path}")

    def _alive(self) -> None:
        if self.process is None:          # a launch's node: launch_testing watches it
            return
        code = self.process.poll()
        if code is not None:
            self.log.flush()
            tail = self.log_path.read_text(errors="replace").strip().splitlines()[-5:]
            raise RuntimeError(f"the node exited with {code}: " + " | ".join(tail))

    def close(self) -> None:
        """Stop the node (SIGINT, as launch does: its recording is then whole) and leave;
        a launch's node is the launch's to stop."""
        if self.process is not None and self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self.log is not None:
            self.log.close()
        self.readers, self.client = {}, None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def lockstep_parameters(scene: str = "release", parameters: dict | None = None) -> dict:
    """The node's parameters for a controller under test: the scene, lockstep with no tick
    of its own, started paused (the test plays or steps it once the controller is up)."""
    return {"scene": scene, "lockstep": True, "lockstep_wait": 0.0, "paused": True} | dict(
        parameters or {})


def reader_hears(reader, guid) -> bool:
    """Whether `reader` has matched the writer of this GUID."""
    try:
        return any(reader.get_matched_publication_data(handle).key == guid
                   for handle in reader.get_matched_publications())
    except Exception:             # noqa: BLE001 - a match arriving meanwhile: ask again
        return False


def ros_value(value) -> str:
    """A parameter's value as `-p NAME:=VALUE` takes it (YAML)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(ros_value(v) for v in value) + "]"
    return str(value)


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

    def __init__(self, arm: WireArm, t: np.ndarray):
        super().__init__()
        self.arm, self.t = arm, t

    def __missing__(self, key):
        from ..recording.rrd.readback import read, table
        if self.arm.recording is None:
            raise KeyError(f"{key}: the node writes no recording (rerun_path), where the "
                           "energy books come from")
        deadline = time.monotonic() + self.arm.silence
        while True:
            columns = _energy_columns(table(read(self.arm.recording)))
            if columns is not None and columns["sim_time"][-1] >= self.t[-1] - 1e-9 or \
                    time.monotonic() > deadline:
                break
            time.sleep(0.2)
        if columns is None:
            raise KeyError(f"{key}: the node's recording {self.arm.recording} has no energy "
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
