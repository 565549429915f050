"""A controller under test over the wire (arm_sim_ros/testing/wire.py): the node in a
subprocess, in lockstep, on a private domain, on loopback; the controller on the dds
transport (testing/controller.py). The loop is ordered by stamps, so the trace is the
in-process one bit for bit, and the same every run."""
import numpy as np
import pytest

from arm_sim_ros.testing.loop import ControllerError, closed_loop
from arm_sim_ros.testing.controller import Controller

TARGET = np.array([0.5, -0.3])
SCENE = {"policy": "command", "gravity": 0.0, "estimate": "off"}


def pd(reading):
    return 60.0 * (TARGET - reading.q) - 12.0 * reading.qd


def test_a_pd_controller_over_the_wire(arm_node):
    node = arm_node("release", SCENE)
    with Controller(pd, node):
        trace = node.run(2.0)
    assert len(trace) == 201 and trace.t[-1] == pytest.approx(2.0)
    assert trace.settle_time(reference=TARGET) < 2.0
    assert trace.books_closed()


def test_over_the_wire_is_the_in_process_loop_bit_for_bit(arm_node):
    """Each answer acts from the tick after the state it answers, as closed_loop's does at
    the node's publish rate: the same arm, the same numbers."""
    node = arm_node("release", SCENE)
    with Controller(pd, node):
        node.run(0.5)
        wire = node.run(0.5)                   # run() goes on from where it stopped
    here = closed_loop(pd, "release", 1.0, overrides={"gravity": 0.0})   # h = 1/rate
    for name in ("q", "qd", "command", "tau"):
        np.testing.assert_array_equal(getattr(wire, name), getattr(here, name), err_msg=name)


def test_two_runs_over_the_wire_give_the_same_trace(arm_node):
    traces = []
    for _ in range(2):
        node = arm_node("release", SCENE | {"sensors.seed": 4,
                                            "sensors.position_noise": [1e-3, 1e-3]})
        with Controller(pd, node):
            traces.append(node.run(1.0))
        node.close()
    for name in ("q", "qd", "measured_q", "measured_qd", "command", "tau"):
        np.testing.assert_array_equal(getattr(traces[0], name), getattr(traces[1], name),
                                      err_msg=name)


def test_a_silent_controller_is_reported_naming_the_state_it_left(arm_node):
    node = arm_node("release", SCENE, silence=1.0)
    with pytest.raises(ControllerError, match=r"no command answered the state at t = 0\.0+ s "
                                              r"within 1 s"):
        node.run(0.1)


def transports():
    """dds always; rclpy where it imports (ROS 2 sourced)."""
    try:
        import rclpy  # noqa: F401
    except ImportError:
        return ["dds"]
    return ["dds", "rclpy"]


@pytest.mark.hunt
@pytest.mark.parametrize("transport", transports())
@pytest.mark.parametrize("busy", [0, 2], ids=["idle", "both cores busy"])
def test_ten_runs_over_the_wire_give_one_trace_idle_or_loaded(arm_node, busy, transport):
    """The same test ten times, with `busy` processes spinning beside it: one trace, bit for
    bit (sensors on, so their draws are part of it), the node on either transport."""
    import hashlib
    import subprocess
    import sys
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
                for _ in range(busy)]
    digests = set()
    try:
        for _ in range(10):
            node = arm_node("release", SCENE | {"sensors.seed": 9,
                                                "sensors.position_noise": [1e-3, 1e-3],
                                                "sensors.velocity": "differences"},
                            transport=transport)
            with Controller(pd, node):
                trace = node.run(2.0)
            node.close()
            digests.add(hashlib.sha256(np.column_stack(
                [trace.t, trace.q, trace.qd, trace.measured_q, trace.measured_qd,
                 trace.command, trace.tau]).tobytes()).hexdigest())
    finally:
        for spinner in spinners:
            spinner.kill()
    assert len(digests) == 1, digests
