"""A controller on this package's dds transport, for tests over the wire with no ROS
installed: a law of the Reading, run in a thread beside the test, answering each JointState
the node publishes once, with that state's stamp in its answer's header (lockstep's
protocol, schedule.Lockstep). What an rclpy or rclcpp controller does is the same: copy the
stamp of the state you answer into your command's header.stamp.

    with Controller(pd, arm):                # or a domain id, from another process
        trace = arm.run(2.0)
"""
from __future__ import annotations

import threading

import numpy as np

from .loop import COMMANDS, Reading, command_pair
from .heard import stamp_of
from .wire import wire_env

WAIT = 0.05          # s a pass waits for a state before it looks whether to stop


class Controller:
    """`law(Reading) -> two numbers` (torques, or set-points with command="position" or
    "velocity"), answering joint_states on joint_commands, in a thread."""

    def __init__(self, law, node, *, command: str = "torque", env=None):
        """`node`: a WireArm (then the answers wait until its trace hears them, so that the
        first is not lost to discovery), or a domain id."""
        if command not in COMMANDS:
            raise ValueError(f"command must be one of {', '.join(COMMANDS)}, got {command!r}")
        self.node = None if isinstance(node, int) else node
        self.domain_id = node if isinstance(node, int) else node.domain_id
        self.law, self.command = law, command
        self.env = wire_env(self.domain_id, env)
        self.answered = 0            # states answered
        self.error = None            # what stopped the thread, if anything did
        self._stop, self._thread = threading.Event(), None

    def start(self) -> "Controller":
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic
        from ..node.wire import messages as msg
        p = self.participant = msg.make_participant(self.domain_id,
                                                    msg.discovery_config(self.env))
        self.states = DataReader(p, Topic(p, "rt/joint_states", msg.JointState),
                                     qos=msg.default_qos(msg.JointState, depth=1000))
        self.commands = DataWriter(p, Topic(p, "rt/joint_commands", msg.JointState),
                                       qos=msg.default_qos(msg.JointState))
        if self.node is not None:         # the trace hears every answer, the first too
            self.node.wait_for_writer(self.commands)
        self._thread = threading.Thread(target=self._serve, name="arm_sim controller",
                                        daemon=True)
        self._thread.start()
        return self

    def _serve(self) -> None:
        from cyclonedds.core import ReadCondition, SampleState, ViewState, InstanceState, WaitSet
        from cyclonedds.util import duration
        from ..node.wire import messages as msg
        ready = WaitSet(self.participant)
        ready.attach(ReadCondition(self.states, SampleState.Any | ViewState.Any |
                                   InstanceState.Any))
        last = None
        try:
            while not self._stop.is_set():
                ready.wait(duration(seconds=WAIT))
                for state in self.states.take(N=1000):
                    if not isinstance(state, msg.JointState):
                        continue
                    stamp = stamp_of(state)
                    if last is not None and stamp <= last:     # a state sent again: answered
                        continue
                    last = stamp
                    self.commands.write(self.answer(state, stamp))
                    self.answered += 1
        except Exception as error:        # noqa: BLE001 - kept for stop(), which raises it
            self.error = error

    def answer(self, state, stamp: int):
        from ..node.wire import messages as msg
        reading = Reading(stamp / 1e9, np.array(state.position[:2], dtype=float),
                          np.array(state.velocity[:2], dtype=float))
        values = list(command_pair(self.law(reading), reading.t, self.command))
        field = "effort" if self.command == "torque" else self.command
        return msg.JointState(header=msg.Header(stamp=state.header.stamp),
                              name=list(state.name[:2]), **{field: values})

    def stop(self) -> None:
        """Stop answering; the law's error, if it raised one, is raised here."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        self.states = self.commands = self.participant = None
        if self.error is not None:
            raise self.error

    def __enter__(self) -> "Controller":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
