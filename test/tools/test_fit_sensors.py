"""`arm-sim fit` on recordings made with sensors (tools/fit/observe.py), against a recording
our simulator did not make (test_fit_reference.sensed_recording: scipy DOP853 on separately
written equations, read by an encoder of 4096 counts with noise, a zero offset, a delay and
differenced velocities made there): a 3 ms loop latency, in the sensors or in the commands,
and the encoders' offsets come back within 5 %."""
from __future__ import annotations

import pytest

from arm_sim_ros.interface import COMMAND_TOPIC
from arm_sim_ros.recording.bags.bag import BagWriter, joint_state, torque_command

from tools.test_fit import base_args, fit
from tools.test_fit_reference import COUNTS, RATE, sensed_recording

OFFSET = (0.02, -0.015)
DURATION = 1.0       # s: the shortest the fit takes (two harmonics in 0.1-2 Hz); 4 s cost 57 s a test
READ = ["--set", f"sensors.rate={RATE:g}", "--set", "sensors.velocity=differences",
        "--set", f"sensors.position_resolution={6.283185307179586 / COUNTS!r},"
                 f"{6.283185307179586 / COUNTS!r}"]


def write_bag(path, rec, commands: bool = False):
    """The readings on /joint_states (effort: the torque as it acts, or with `commands` the
    commands on joint_torque_commands beside them)."""
    with BagWriter(path) as bag:
        bag.add_topic("/joint_states", "sensor_msgs/msg/JointState")
        if commands:
            bag.add_topic("/" + COMMAND_TOPIC, "std_msgs/msg/Float64MultiArray")
        for t, q, qd, tau in zip(rec.t, rec.q, rec.qd, rec.tau):
            ns = round(t * 1e9)
            if commands:
                bag.write("/" + COMMAND_TOPIC, ns, torque_command(tau))
            bag.write("/joint_states", ns, joint_state(ns, q, qd, tau))
    return str(path)


def read_late():
    """The sensed recording whose readings are 3 ms late (one, cached, for every test here)."""
    return sensed_recording(DURATION, sensor_delay=0.003, offset=OFFSET)[0]


def found(outcome) -> dict:
    return {p["key"]: p for p in outcome["parameters"]}


def assert_within(parameter, truth, share=0.05):
    assert abs(parameter["value"] - truth) < share * abs(truth), parameter
    assert abs(parameter["value"] - truth) < 3 * parameter["se"] + 1e-12, parameter


def test_a_3_ms_sensor_delay_and_the_encoder_offsets_are_found_within_5_percent(capsys,
                                                                                tmp_path):
    bag = write_bag(tmp_path / "read", read_late())
    outcome = fit(capsys, bag, *base_args(), *READ, "--free",
                  "sensors.delay,sensors.position_offset", "--starts", "1", "--workers", "1")
    keys = found(outcome)
    assert_within(keys["sensors.delay"], 0.003)
    assert_within(keys["sensors.position_offset[0]"], OFFSET[0])
    assert_within(keys["sensors.position_offset[1]"], OFFSET[1])
    assert outcome["converged"]


def test_a_3_ms_command_delay_is_found_within_5_percent_from_the_commands(capsys, tmp_path):
    bag = write_bag(tmp_path / "late", sensed_recording(DURATION, sensor_delay=0.0,
                                                        command_delay=0.003,
                                                        offset=OFFSET)[0], commands=True)
    outcome = fit(capsys, bag, *base_args(), *READ, "--set", f"sensors.position_offset="
                  f"{OFFSET[0]},{OFFSET[1]}", "--free", "command_delay", "--torque-topic",
                  COMMAND_TOPIC, "--starts", "1", "--workers", "1")
    assert_within(found(outcome)["command_delay"], 0.003)


def test_a_command_delay_is_refused_where_the_effort_is_the_torque_as_it_acts(capsys,
                                                                             tmp_path):
    bag = write_bag(tmp_path / "read", read_late())
    line = fit(capsys, bag, *base_args(), "--free", "command_delay", code=2)
    assert "--torque-topic" in line


@pytest.mark.parametrize("key", ["sensors.position_noise", "sensors.rate", "sensors.seed"])
def test_sensor_keys_a_recording_does_not_identify_are_refused(capsys, tmp_path, key):
    bag = write_bag(tmp_path / "read", read_late())
    line = fit(capsys, bag, *base_args(), "--free", key, code=2)
    assert "not a key a fit can free" in line and "sensors keys: position_offset, delay" in line
