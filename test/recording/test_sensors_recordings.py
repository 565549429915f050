"""Recordings of a scene with sensors (issue 37): `--csv` keeps q1 q2 qd1 qd2 as the truth and
adds the readings; `arm-sim run --bag` and `arm-sim record` keep /joint_states (readings) and
/arm_sim/true_joint_states (truth) at the same stamps; Rerun records the measured series and
draws them over the true ones. Every value is the offline simulator's, bit for bit."""
from __future__ import annotations

import csv

import pytest

from arm_sim_ros.interface import NODE_TOPICS, SENSOR_TOPICS, TRUE_JOINT_STATES
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.recording.rrd import blueprint
from arm_sim_ros.recording.readouts import Snapshot
from arm_sim_ros.tools import cli

from recording.test_bag import ISOLATED, read_bag, start_recording, wait_matched, wire
from recording.test_telemetry import blueprint_rows, read_back, scalars

SENSORS = ["--set", "sensors.position_noise=1e-3,2e-3", "--set", "sensors.delay=0.002",
           "--set", "sensors.position_resolution=0.0015339807878856412,0.0015339807878856412",
           "--set", "sensors.velocity=differences", "--set", "step_size=0.001"]
SCENE = load_scene("release").replace(step_size=0.001, sensors={
    "position_noise": [1e-3, 2e-3], "delay": 0.002, "velocity": "differences",
    "position_resolution": [0.0015339807878856412] * 2})


def offline(steps: int):
    """[(state q, q̇), readings] at t = 0 and after each step."""
    sim, out = Simulator(SCENE), []
    out.append((sim.state[:4], sim.readings))
    for _ in range(steps):
        sim.step()
        out.append((sim.state[:4], sim.readings))
    return out


def test_csv_keeps_the_truth_and_adds_the_measured_columns(tmp_path):
    path = tmp_path / "run.csv"
    assert cli.main(["run", "--scene", "release", *SENSORS, "--duration", "0.3",
                     "--csv", str(path)]) == 0
    with open(path, newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert list(rows[0])[:9] == ["t", "q1", "q2", "qd1", "qd2", "q1_measured", "q2_measured",
                                 "qd1_measured", "qd2_measured"]
    names = ("q1", "q2", "qd1", "qd2")
    for row, (state, reading) in zip(rows, offline(300), strict=True):
        assert tuple(float(row[n]) for n in names) == state
        assert tuple(float(row[f"{n}_measured"]) for n in names) == reading


def test_a_run_bag_records_the_readings_and_the_truth_beside_them(capsys, tmp_path):
    path = tmp_path / "bag"
    assert cli.main(["run", "--scene", "release", *SENSORS, "--duration", "0.3",
                     "--publish-rate", "100", "--bag", str(path)]) == 0
    capsys.readouterr()
    messages, connections = read_bag(path)
    assert set(connections) == set(NODE_TOPICS) - {"/joint_torque_commands"} | set(
        SENSOR_TOPICS)
    expected = offline(300)[::10]
    for topic, part in (("/joint_states", 1), (TRUE_JOINT_STATES, 0)):
        got = [tuple(m.position) + tuple(m.velocity) for _, m, _ in messages[topic]]
        assert got == [e[part] for e in expected], topic
    stamps = {topic: [m.header.stamp.nanosec for _, m, _ in messages[topic]]
              for topic in ("/joint_states", TRUE_JOINT_STATES)}
    assert stamps["/joint_states"] == stamps[TRUE_JOINT_STATES]


def test_a_run_bag_without_sensors_has_no_truth_topic(capsys, tmp_path):
    assert cli.main(["run", "--scene", "release", "--duration", "0.1",
                     "--bag", str(tmp_path / "bag")]) == 0
    capsys.readouterr()
    assert TRUE_JOINT_STATES not in read_bag(tmp_path / "bag")[1]


def test_record_of_a_node_with_sensors_keeps_both_topics(tmp_path):
    from arm_sim_ros.node.transports.dds import DdsArmSimNode
    from arm_sim_ros.tools.wire.record import DEFAULT_TOPICS

    domain = 162
    recorder = wire.make_participant(domain, ISOLATED)
    finish = start_recording(tmp_path / "bag", dict(DEFAULT_TOPICS), recorder)
    try:
        node = DdsArmSimNode({"scene": "release", "step_size": 0.001, "publish_rate": 100.0,
                              "sensors.position_noise": [1e-3, 2e-3], "sensors.delay": 0.002,
                              "sensors.velocity": "differences",
                              "sensors.position_resolution": [0.0015339807878856412] * 2},
                             domain_id=domain, config=ISOLATED, wall_clock=lambda: 100.0,
                             start_stamp_ns=0)
        wait_matched([node.joint_state_writer])
        node.tick()
        wait_matched([node.truth_writer])
        for _ in range(29):
            node.tick()
        for w in (node.joint_state_writer, node.truth_writer):
            assert w.wait_for_acks(5_000_000_000)
    finally:
        result = finish()
    assert result["/joint_states"] == 30 and result[TRUE_JOINT_STATES] >= 29
    messages, _ = read_bag(tmp_path / "bag")
    expected = {round((k + 1) * 1e7): e for k, e in enumerate(offline(300)[10::10])}
    for topic, part in (("/joint_states", 1), (TRUE_JOINT_STATES, 0)):
        for _, m, _ in messages[topic]:
            stamp = m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
            assert tuple(m.position) + tuple(m.velocity) == expected[stamp][part], topic
    node.close()


def test_rerun_records_the_measured_series_and_draws_them_over_the_true_ones(tmp_path):
    path = tmp_path / "run.rrd"
    assert cli.main(["run", "--scene", "release", *SENSORS, "--duration", "0.3",
                     "--rerun", str(path)]) == 0
    columns = read_back(path)
    expected = offline(300)
    for path_, at in (("joints/angle_measured", slice(0, 2)),
                      ("joints/velocity_measured", slice(2, 4))):
        assert scalars(columns[path_]).tolist() == [list(r[at]) for _, r in expected], path_
    assert scalars(columns["joints/angle"]).tolist() == [list(s[:2]) for s, _ in expected]
    contents = {str(row.get("ViewContents:query")) for row in blueprint_rows(path).values()}
    names = {str(row.get("ViewBlueprint:display_name")) for row in blueprint_rows(path).values()}
    assert {"['joints/angle', 'joints/angle_measured']",
            "['joints/velocity', 'joints/velocity_measured']"} <= contents
    assert sum("measured over true" in name for name in names) == 2
    snap = Snapshot(Simulator(SCENE))
    styles = blueprint.series(snap)
    assert styles["joints/angle"][2] == (blueprint.WIDE, blueprint.WIDE)   # truth beneath
    assert styles["joints/angle_measured"][0] == ("q1 measured", "q2 measured")


@pytest.mark.parametrize("sensors", [None, {"seed": 3}], ids=["absent", "modelling nothing"])
def test_without_sensors_no_measured_series(sensors):
    snap = Snapshot(Simulator(SCENE.replace(sensors=sensors)))
    assert ("joints/angle_measured" in blueprint.series(snap)) == (sensors is not None)


def test_a_servo_scene_with_sensors_records_its_effects_document(tmp_path):
    """The servo's interface names and the sensors' velocity are text in the effects table
    (a servo scene's recording once failed on them: format code 'g' for a str)."""
    snap = Snapshot(Simulator(load_scene("servo_hold").replace(
        sensors={"velocity": "differences", "position_resolution": [0.006, 0.006]},
        command_delay=0.002)))
    document = blueprint.effects_document(snap)
    assert "| servo | interface | position, position | position/velocity/effort |" in document
    assert "| sensors, latency | seed | 0 |  |" in document
    assert "|  | position_resolution | 0.006, 0.006 | rad per count |" in document
    assert "|  | velocity | differences | differences/true |" in document
    assert "|  | command_delay | 0.002 | s |" in document
    path = tmp_path / "servo.rrd"
    assert cli.main(["run", "--scene", "servo_hold", "--duration", "0.05", "--rerun",
                     str(path)]) == 0
    assert len(read_back(path)["joints/angle"]["sim_time"]) == 51


def test_the_torque_a_control_loop_applies_is_recorded_step_by_step(tmp_path):
    """Under a control loop the drive's torque changes every step: the recording's joint
    torque and the CSV's tau are each step's own, not the last one of a batch."""
    args = ["--scene", "servo_hold", *SENSORS, "--set", "command_delay=0.002",
            "--duration", "0.4"]
    assert cli.main(["run", *args, "--rerun", str(tmp_path / "run.rrd"),
                     "--csv", str(tmp_path / "run.csv")]) == 0
    sim = Simulator(load_scene("servo_hold").replace(sensors=SCENE.sensors,
                                                     command_delay=0.002))
    torques = [sim.joint_torque()]
    for _ in range(400):
        sim.step()
        torques.append(sim.joint_torque())
    assert len(set(torques)) > 100                     # it changes from step to step
    recorded = scalars(read_back(tmp_path / "run.rrd")["joints/torque"])
    assert [tuple(t) for t in recorded.tolist()] == torques
    with open(tmp_path / "run.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert [(float(r["tau1"]), float(r["tau2"])) for r in rows] == torques
