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
import time
from pathlib import Path

from .heard import Heard
from .loop import ControllerError
from .trace import Trace

DOMAINS = range(80, 120)          # private domains: the project's own tests use others
START_TIMEOUT = 120.0             # s: a first run compiles the scene's kernels (tens of s)
SILENCE = 10.0                    # s of wall time with the latest state unanswered: the
                                  # controller is gone
DRAIN = 0.02                      # s between two looks at the states while a run goes on
_taken = itertools.count()


def private_domain() -> int:
    """A domain id from DOMAINS this process has not used yet, apart from pytest-xdist's
    other workers' (ARM_SIM_TEST_DOMAIN chooses one)."""
    chosen = os.environ.get("ARM_SIM_TEST_DOMAIN")
    if chosen:
        return int(chosen)
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")[2:]    # else apart by process id
    offset = int(worker) * 10 if worker.isdigit() else os.getpid() % len(DOMAINS)
    return DOMAINS[(offset + next(_taken)) % len(DOMAINS)]


def wire_env(domain_id: int, env=None) -> dict:
    """The environment a node on this domain runs in: loopback discovery, as a ROS 2 peer's."""
    env = dict(os.environ if env is None else env)
    env.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.pop("ROS_STATIC_PEERS", None)
    return env


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
                   "--ros-args",
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
        from ..node.wire import messages as msg
        from ..tools.wire.sim_client import SimulationClient

        self.domain_id, self.env, self.silence = domain_id, env, silence
        self.scene, self.publish_rate = values["scene"], float(values.get("publish_rate", 100.0))
        self.client = SimulationClient(domain_id, msg.discovery_config(env))
        self.heard = Heard(self.client.participant,
                           Path(values["rerun_path"]) if values.get("rerun_path") else None)
        self.recording = self.heard.recording
        self._replied = WaitSet(self.client.participant)
        self._replied.attach(ReadCondition(self.client.services["step_simulation"].reader,
                                           SampleState.Any | ViewState.Any | InstanceState.Any))

    # -- running ----------------------------------------------------------------------------

    def run(self, seconds: float) -> Trace:
        """`seconds` more of simulated time, one tick per answered state; the trace of the
        whole run so far."""
        from cyclonedds.util import duration
        ticks = round(seconds * self.publish_rate)
        end = max(self.heard.states) + ticks * round(1e9 / self.publish_rate)
        reply = self.client.services["step_simulation"].ask(steps=ticks)
        seen, quiet_since = len(self.heard.states), time.monotonic()
        # Blocked on the reply, the states waiting in the readers (no work of ours a tick):
        # a look at them now and then tells a loop that goes on from one gone silent. A
        # state answered and not yet followed, or the run's last state heard, is the node's
        # time (a first tick compiles the scene's kernels: tens of seconds), not the
        # controller's.
        while (answer := reply()) is None:
            self._replied.wait(duration(seconds=DRAIN))
            self.heard.take()
            now = time.monotonic()
            latest = max(self.heard.states)
            if len(self.heard.states) != seen:
                seen, quiet_since = len(self.heard.states), now
            elif latest in self.heard.answers or latest >= end:
                self._alive()
                if now - quiet_since > START_TIMEOUT:
                    raise ControllerError(self._stuck(), self.trace())
            elif now - quiet_since > self.silence:
                self._alive()
                raise ControllerError(self._silent(), self.trace())
        if answer.result.result != 1:
            raise ControllerError(f"the node refused to step: {answer.result.error_message}",
                                  self.trace())
        # Every state up to the last is here, and the answer each before it had (the node
        # ticked on it, so it was sent): samples of three topics arrive in any order.
        deadline = time.monotonic() + self.silence
        while time.monotonic() < deadline and not self._whole(end):
            self.heard.take()
            time.sleep(0.0002)
        return self.trace()

    def _whole(self, end: int) -> bool:
        heard = self.heard
        return max(heard.states, default=-1) >= end and all(
            stamp in heard.answers for stamp in heard.states if stamp < end)
        return self.trace()

    def _first_state(self, deadline: float) -> bool:
        """Until the state the node awaits an answer to at start is here (it comes once this
        reader has matched: every trace starts at that state), or `deadline`."""
        while not self.heard.states and time.monotonic() < deadline:
            self._alive()
            time.sleep(DRAIN)
            self.heard.take()
        return bool(self.heard.states)

    def wait_for_writer(self, writer) -> None:
        """Until this trace's command reader has matched `writer` (a controller in this
        process: its answers are then all heard, the first too)."""
        deadline = time.monotonic() + self.silence
        while not self.heard.hears(writer):
            if time.monotonic() > deadline:
                raise TimeoutError(f"the trace did not hear the controller's writer on domain "
                                   f"{self.domain_id} within {self.silence:g} s")
            time.sleep(0.001)

    def _silent(self) -> str:
        return (f"no command answered the state at {self._at()} within {self.silence:g} s "
                f"(wall): the controller went silent, or answers without the state's stamp "
                f"in its header; domain {self.domain_id}, node log {self.log_path}")

    def _stuck(self) -> str:
        return (f"the node did not step within {START_TIMEOUT:g} s (wall) of the answer to "
                f"its state at {self._at()}; domain {self.domain_id}, node log {self.log_path}")

    def _at(self) -> str:
        return f"t = {(max(self.heard.states) - min(self.heard.states)) / 1e9:.6f} s"

    def trace(self) -> Trace:
        """The trace of the whole run so far (heard.Heard.trace)."""
        return self.heard.trace(self.scene, self.silence, {"log": str(self.log_path)})

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
            missing = self.client.unmatched() or ["its first state"]
            self.close()
            raise TimeoutError(f"the node did not come up on domain {self.domain_id} within "
                               f"{START_TIMEOUT:g} s (not heard: {', '.join(missing)}); its "
                               f"log: {self.log_path}")

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
        self.heard = self.client = self._replied = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def lockstep_parameters(scene: str = "release", parameters: dict | None = None) -> dict:
    """The node's parameters for a controller under test: the scene, lockstep with no tick
    of its own, started paused (the test plays or steps it once the controller is up)."""
    return {"scene": scene, "lockstep": True, "lockstep_wait": 0.0, "paused": True} | dict(
        parameters or {})


def ros_value(value) -> str:
    """A parameter's value as `-p NAME:=VALUE` takes it (YAML)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(ros_value(v) for v in value) + "]"
    return str(value)
