"""Issue 17: a Rerun recording that tells the run's story and lines up with its bag.

Read back with rr.chunk.RrdReader (recording/rrd/readback.py and test_telemetry.read_back):
timelines (sim_time, ros_time = the JointState stamps, log_time = wall clock), the scene as
recording properties, the arm stored y up with the flip in the view, units on every series,
the node's per-tick story, and `arm-sim inspect`.
"""
import csv
import io
import math
import time

import numpy as np
import pytest
import rerun as rr
from rosbags.rosbag2 import Reader

from arm_sim_ros.node import core as node_core
from arm_sim_ros.node.params import parameters as node_params
from arm_sim_ros.node.recorder_link import RecorderLink
from arm_sim_ros.physics.stepping.integrators import INTEGRATORS
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.recording.rrd import blueprint, readback, telemetry
from arm_sim_ros.recording import readouts
from arm_sim_ros.recording.bags.bag import TYPESTORE
from arm_sim_ros.tools import cli

from recording.test_telemetry import Log, blueprint_rows, read_back, record, scalars

STAMP_ORIGIN = 1_763_900_000_123_456_789   # a wall-clock start stamp, ns


def bag_joint_states(path):
    """[(bag time ns, header stamp ns, positions)] of /joint_states."""
    out = []
    with Reader(path) as reader:
        for connection, timestamp, raw in reader.messages():
            if connection.topic == "/joint_states":
                m = TYPESTORE.deserialize_cdr(raw, connection.msgtype)
                out.append((timestamp, m.header.stamp.sec * 10**9 + m.header.stamp.nanosec,
                            list(m.position)))
    return out


def at(entity, timeline):
    """{time on `timeline`: scalars} of an entity read back."""
    return dict(zip(entity[timeline], entity["Scalars:scalars"]))


# --- 1. timelines that line up ----------------------------------------------------------

def test_a_node_recording_is_on_the_clock_of_its_joint_states(tmp_path):
    """Every JointState the node publishes (stamp_ns) is a row of the recording at that
    ros_time with the same positions, across a reset too; sim_time runs beside it."""
    path = tmp_path / "node.rrd"
    config = node_params.resolve_parameters({"scene": "damped_release", "rerun_path": str(path),
                                             "publish_rate": 50.0})
    core = node_core.ArmSimCore(config, Log(), wall_clock=lambda: 0.0,
                                start_stamp_ns=STAMP_ORIGIN)
    published = []
    for k in range(40):
        if k == 25:
            core.reset()
        published.append(core.tick(0.0))
    core.finish()
    columns = read_back(path)["joints/angle"]
    rows = {}   # a reset's initial row shares the stamp of the run's last step: keep both
    for stamp, angle in zip(columns["ros_time"], columns["Scalars:scalars"]):
        rows.setdefault(stamp, []).append(angle)
    for js in published:
        assert rows[js.stamp_ns][-1 if js is not published[24] else 0] == js.position
    assert len(rows[published[24].stamp_ns]) == 2      # the old run's end, the reset's start
    offsets = {r - s for r, s in zip(columns["ros_time"], columns["sim_time"])}
    assert offsets == {STAMP_ORIGIN}


def test_arm_sim_run_rerun_and_bag_of_one_run_line_up_on_ros_time(tmp_path, capsys):
    rrd, bag = tmp_path / "run.rrd", tmp_path / "bag"
    before = time.time_ns()
    assert cli.main(["run", "--scene", "damped_release", "--duration", "0.5",
                     "--rerun", str(rrd), "--bag", str(bag), "--publish-rate", "20"]) == 0
    after = time.time_ns()
    capsys.readouterr()
    columns = read_back(rrd)
    angles = at(columns["joints/angle"], "ros_time")
    states = bag_joint_states(bag)
    assert len(states) == 11
    bag_origin = states[0][0]                   # bag time: the wall clock at start + sim time
    assert before <= bag_origin <= after
    for log_ns, stamp, position in states:      # offline stamps: simulated time from 0
        assert log_ns == bag_origin + stamp
        assert np.allclose(angles[stamp], position, atol=0, rtol=0)
    assert columns["joints/angle"]["ros_time"] == columns["joints/angle"]["sim_time"]
    # log_time: the wall clock when the recorder got each row, in order, within the run
    wall = columns["energy/total"]["log_time"]
    assert before <= wall[0] and wall[-1] <= after and wall == sorted(wall)
    for entity in ("events", "arm/links", "books/loss/dissipated"):
        assert {"sim_time", "ros_time", "log_time"} <= set(columns[entity])


# --- 2. the scene as data ----------------------------------------------------------------

def test_the_scene_effects_and_integrator_are_recording_properties(tmp_path):
    scene = load_scene("geared_arm").replace(duration=0.02)
    record(scene, tmp_path / "geared.rrd")
    props = readback.properties(tmp_path / "geared.rrd")
    assert props["recording"]["name"] == "arm_sim geared_arm"
    s = props["scene"]
    assert s["name"] == "geared_arm" and s["policy"] == "command_gravity_compensation"
    assert s["step_size"] == scene.step_size and s["link_lengths"] == list(scene.link_lengths)
    assert s["damping"] == scene.damping and "gear_ratio" in s["motors"]   # tables as JSON
    sim = Simulator(scene)
    assert props["effects"]["names"] == [e.name for e in sim.dynamics.active]
    assert props["effect.motors"]["parameter"][0] == "gear_ratio"
    assert props["effect.gravity"]["unit"] == "m/s²"
    method = INTEGRATORS["exponential_rk4"]          # RK4's tableau, the windings exact
    i = props["integrator"]
    assert (i["name"], i["order"], i["stages"]) == ("exponential_rk4", 4, 4)
    assert i["b"] == [float(b) for b in method.b] and i["c"] == [float(c) for c in method.c]
    assert i["step_size"] == 0.001 and i["substeps_per_step"] == sim.substeps == 1
    assert props["clock"]["source"] == "arm-sim run" and props["clock"]["stamp_origin_ns"] == 0


# --- 3. physics coordinates, units --------------------------------------------------------

def test_the_arm_is_stored_y_up_and_the_view_flips_it(tmp_path):
    scene = load_scene("release").replace(initial_positions=(0.5, 0.0), duration=0.01)
    record(scene, tmp_path / "up.rrd")
    columns = read_back(tmp_path / "up.rrd")
    _, elbow, tip = columns["arm/joints"]["Points2D:positions"][0]
    assert elbow[1] > 0 and tip[1] > 0          # q1 = 0.5 rad: above the shoulder, y up
    _, statics, _ = readback.read(tmp_path / "up.rrd")
    assert statics["arm"]["Transform3D:scale"] == [1.0, -1.0, 1.0]
    rows = blueprint_rows(tmp_path / "up.rrd")
    arm_view = next(r for r in rows.values()
                    if str(r.get("ViewBlueprint:display_name", [""])[0]).startswith("Arm (y up"))
    assert arm_view["ViewBlueprint:space_origin"] == ["/"]
    assert ["+ arm/**"] in [r.get("ViewContents:query") for r in rows.values()]


@pytest.mark.parametrize("name", ["geared_arm", "springs_oscillation"])
def test_every_series_has_its_unit(tmp_path, name):
    scene = load_scene(name).replace(duration=0.02)
    record(scene, tmp_path / "units.rrd")
    props, statics, temporal = readback.read(tmp_path / "units.rrd")
    series = [e for e, parts in temporal.items() if "Scalars:scalars" in parts[0]]
    assert series and sorted(series) == sorted(props["units"]["path"])
    for entity in series:
        assert statics[entity]["unit"] == blueprint.unit(entity) != "", entity
    assert statics["joints/velocity"]["unit"] == "rad/s"


# --- 4. the node's story ------------------------------------------------------------------

STORY = ("node/commands_refused", "node/late_ticks", "node/real_time_factor", "node/substeps")


def test_the_node_records_refused_commands_substeps_and_commanded_vs_applied_per_tick(tmp_path):
    path = tmp_path / "story.rrd"
    config = node_params.resolve_parameters({
        "scene": "release", "policy": "command", "rerun_path": str(path), "publish_rate": 50.0,
        "command_timeout": 0.0, "step_size": 0.005})
    assert config.steps_per_tick == 4
    core = node_core.ArmSimCore(config, Log(), wall_clock=lambda: 0.0, start_stamp_ns=0)
    refused_at = {3: 2, 7: 1}     # tick: commands refused before it
    for k in range(12):
        for _ in range(refused_at.get(k, 0)):
            core.on_command([math.nan, 0.0])
        if k == 5:
            core.on_command([1.5, -0.5])
        core.tick(0.0)
    core.finish()
    columns = read_back(path)
    h_ns = 5_000_000
    ticks = [(k + 1) * 4 * h_ns for k in range(12)]   # each tick's row: its last step
    for entity in STORY:
        assert columns[entity]["sim_time"] == ticks, entity
    assert scalars(columns["node/commands_refused"])[:, 0].tolist() == [
        refused_at.get(k, 0) for k in range(12)]
    assert scalars(columns["node/substeps"])[:, 0].tolist() == [4] * 12
    commanded = at(columns["joints/commanded_torque"], "sim_time")
    applied = at(columns["joints/torque"], "sim_time")
    assert commanded[ticks[4]] == [0.0, 0.0] and commanded[ticks[5]] == [1.5, -0.5]
    assert applied[ticks[5]] == [1.5, -0.5]      # the command policy applies it as given
    names = {r.get("ViewBlueprint:display_name", [None])[0]
             for r in blueprint_rows(path).values()}
    assert {"Refused commands / tick", "Real-time factor", "Late ticks", "Sub-steps / tick",
            "Torque & command (N m)"} <= names


def test_the_links_tick_story_has_real_time_factor_and_late_ticks(tmp_path):
    """What the core hands RecorderLink.step each tick: its wall time and late-tick count."""
    scene = load_scene("release").replace(step_size=0.01)
    sim = Simulator(scene)
    recorder = telemetry.make_recorder(scene, path=str(tmp_path / "link.rrd"))
    link = RecorderLink(Log(), recorder, sim, stamp_origin_ns=STAMP_ORIGIN)
    walls = [0.0, 0.02, 0.04, 0.1, 0.125, 0.13]    # 2 steps a tick: 0.02 s simulated
    late = [0, 0, 0, 1, 1, 1]
    for wall, count in zip(walls, late):
        link.step(2, wall_now=wall, late_ticks=count)
    link.finish()
    columns = read_back(tmp_path / "link.rrd")
    rtf = scalars(columns["node/real_time_factor"])[:, 0]
    # over the last RTF_WINDOW (0.1 s) of wall time: simulated s / wall s
    assert math.isnan(rtf[0]) and np.allclose(rtf[1:], [1.0, 1.0, 0.6, 0.06 / 0.105, 0.08 / 0.11])
    assert scalars(columns["node/late_ticks"])[:, 0].tolist() == [0, 0, 0, 1, 0, 0]
    assert columns["node/late_ticks"]["ros_time"] == [
        STAMP_ORIGIN + (k + 1) * 20_000_000 for k in range(6)]


# --- 5. read it back: arm-sim inspect -----------------------------------------------------

def inspect_main(argv):
    """`arm-sim inspect ...`, as cli.main runs it."""
    return cli.main(["inspect", *argv])


def test_inspect_prints_the_properties_and_the_series_as_csv(tmp_path, capsys):
    path = tmp_path / "damped.rrd"
    rows, _ = record(load_scene("damped_release").replace(duration=0.2), path)
    assert inspect_main([str(path)]) == 0
    out = capsys.readouterr().out
    comments = [line for line in out.splitlines() if line.startswith("# ")]
    assert "# recording.name = arm_sim damped_release" in comments
    assert "# scene.step_size = 0.01" in comments and "# integrator.name = rk4" in comments
    assert '# effects.names = ["gravity", "damping"]' in comments
    table = list(csv.reader(io.StringIO("\n".join(l for l in out.splitlines()
                                                  if not l.startswith("# ")))))
    header, body = table[0], table[1:]
    assert header[:3] == ["sim_time [s]", "ros_time [ns]", "log_time [ns]"]
    assert "energy/total:total E = kinetic + gravity [J]" in header
    assert "joints/angle:q1 shoulder [rad]" in header and "joints/angle:q2 elbow [rad]" in header
    assert len(body) == len(rows) == 21
    col = header.index("books/loss/dissipated:loss: damping ∫d·q̇²dt [J]")
    for row, sample in zip(body, rows):
        assert float(row[0]) == pytest.approx(sample.t, abs=1e-12)
        assert int(row[1]) == round(sample.t * 1e9)
        assert float(row[col]) == sample.channels["dissipated"]     # repr: exact
    assert inspect_main([str(path), "--properties"]) == 0
    assert all(line.startswith("# ") for line in capsys.readouterr().out.splitlines())
    assert inspect_main([str(path), "--no-properties", "--every", "5"]) == 0
    assert len(capsys.readouterr().out.splitlines()) == 1 + 5


def test_inspect_refuses_a_missing_or_foreign_file_in_one_line(tmp_path, capsys):
    assert inspect_main([str(tmp_path / "none.rrd")]) == 2
    (tmp_path / "text.rrd").write_text("not a recording")
    assert inspect_main([str(tmp_path / "text.rrd")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 2 and "Traceback" not in err


def test_inspect_is_an_arm_sim_subcommand():
    assert "inspect" in cli.build_parser().format_help()


# --- 6. the arm in 3D from the URDF -------------------------------------------------------

def test_the_urdf_arm_is_logged_once_and_its_joints_follow_the_simulated_angles(tmp_path):
    scene = load_scene("effort_limited_hold").replace(duration=0.05)
    rows, _ = record(scene, tmp_path / "arm3d.rrd")
    _, statics, temporal = readback.read(tmp_path / "arm3d.rrd")
    assert {"arm3d/two_link_arm", "arm3d/com/link1", "arm3d/com/link2", "arm3d/gravity",
            "tf_static"} <= set(statics)
    assert statics["arm3d/com/link2"]["CoordinateFrame:frame"] == "link2"
    assert statics["arm3d/com/link2"]["Points3D:positions"] == [0.5, 0.0, 0.0]
    assert statics["arm3d/gravity"]["Arrows3D:vectors"] == pytest.approx([0.0, -0.4905, 0.0])
    columns = read_back(tmp_path / "arm3d.rrd")
    frames = rows[::max(1, round(0.005 / scene.step_size))]
    for joint, k in (("shoulder_joint", 0), ("elbow_joint", 1)):
        entity = columns[f"arm3d/joints/{joint}"]
        assert entity["sim_time"] == [round(r.t * 1e9) for r in frames]
        for row, (x, y, z, w) in zip(frames, (q[0] for q in entity["Transform3D:quaternion"])):
            angle = row.q[k]     # a turn about +z by the joint's angle
            assert (x, y) == (0.0, 0.0)
            assert np.allclose([z, w], [math.sin(angle / 2), math.cos(angle / 2)], atol=1e-6) or \
                np.allclose([z, w], [-math.sin(angle / 2), -math.cos(angle / 2)], atol=1e-6)
    arrows = np.array([v[0] for v in columns["arm3d/torque/shoulder_joint"]["Arrows3D:vectors"]])
    assert np.allclose(arrows[:, 2], [0.05 * r.tau[0] for r in frames], rtol=1e-6)


def test_an_arm_other_than_the_urdfs_gets_no_3d_view(tmp_path):
    record(load_scene("release").replace(link_lengths=(0.8, 1.2), com_distances=(0.4, 0.6),
                                         duration=0.02), tmp_path / "other.rrd")
    _, statics, temporal = readback.read(tmp_path / "other.rrd")
    assert not [e for e in (*statics, *temporal) if e.startswith("arm3d")]
    names = {r.get("ViewBlueprint:display_name", [None])[0]
             for r in blueprint_rows(tmp_path / "other.rrd").values()}
    assert not [n for n in names if n and "3D" in n]


def test_a_payload_is_no_link_the_scene_still_gets_the_urdf_arm_in_3d(tmp_path):
    """payload_release folds its payload into link 2 for the physics; the URDF's links are
    the scene's bare links, so the 3D arm is shown."""
    record(load_scene("payload_release").replace(duration=0.02), tmp_path / "payload.rrd")
    _, statics, temporal = readback.read(tmp_path / "payload.rrd")
    assert "arm3d/two_link_arm" in statics and "arm3d/joints/elbow_joint" in temporal
    names = {r.get("ViewBlueprint:display_name", [None])[0]
             for r in blueprint_rows(tmp_path / "payload.rrd").values()}
    assert [n for n in names if n and "3D" in n]


# --- 7. can I trust this run? -------------------------------------------------------------

def blueprint_tree(path):
    """(the tab the viewer opens: {display name, views: {view name: (its entity query, its
    origin, {entity: series names it overrides})}}) of a recording's saved blueprint."""
    reader = rr.chunk.RrdReader(str(path))
    (store,) = reader.blueprints()
    rows, names = {}, {}
    for chunk in reader.stream(store=store):
        batch = chunk.to_record_batch()
        entity = chunk.entity_path
        for field in batch.schema.names:
            values = [v for v in batch.column(field).to_pylist() if v is not None] \
                if ":" in field and "time" not in field else []
            if values:
                rows.setdefault(entity, {})[field] = values[-1]
        if "/ViewContents/overrides/" in entity and "SeriesLines:names" in batch.schema.names:
            view, _, rest = entity.partition("/ViewContents/overrides/")
            names.setdefault(view, {})[rest.partition("/visualizers")[0]] = [
                v for v in batch.column("SeriesLines:names").to_pylist() if v][-1]
    (root,) = [r for r in rows.values() if "ContainerBlueprint:active_tab" in r]
    opened = "/" + root["ContainerBlueprint:active_tab"][0]
    views = {}

    def walk(entity):
        for child in rows[entity].get("ContainerBlueprint:contents", []):
            child = "/" + child
            if child.startswith("/container/"):
                walk(child)
            else:
                views[rows[child]["ViewBlueprint:display_name"][0]] = (
                    rows.get(child + "/ViewContents", {}).get("ViewContents:query"),
                    rows[child].get("ViewBlueprint:space_origin", [None])[0],
                    names.get(child, {}))
    walk(opened)
    return {"name": rows[opened].get("ContainerBlueprint:display_name", [None])[0],
            "views": views}


def test_the_viewer_opens_on_can_i_trust_this_run(tmp_path):
    """One tab, open first: the residual (J), each step's local error estimate and their
    sum (rad, rad/s) with the tolerance, the sub-steps, and the events; every series named
    with its unit."""
    path = tmp_path / "trust.rrd"
    record(load_scene("damped_release").replace(duration=0.2, tolerance=2e-3), path)
    tab = blueprint_tree(path)
    assert tab["name"] == "Can I trust this run?"
    views = tab["views"]
    shown = {tuple(query or ()): (name, origin, named) for name, (query, origin, named)
             in views.items()}
    residual, local, accumulated, substeps = (shown[(p,)] for p in (
        "energy/balance_residual", "accuracy/local_error", "accuracy/accumulated_error",
        "accuracy/substeps"))
    assert "[J]" in residual[0] and residual[2] == {
        "energy/balance_residual": ["residual E−E₀−inputs+losses [J]"]}
    assert "[rad, rad/s]" in local[0] and "tolerance 0.002 per s" in local[0]
    assert local[2] == {"accuracy/local_error": ["local error estimate [rad, rad/s]"]}
    assert accumulated[2] == {"accuracy/accumulated_error":
                              ["accumulated error estimate [rad, rad/s]"]}
    assert substeps[2] == {"accuracy/substeps": ["sub-steps per step [1]"]}
    (events,) = [name for name, (_, origin, _) in views.items() if origin == "events"]
    assert events.startswith("Events")
    assert len(views) == 5
    # ...and the rest is one tab away, as before
    assert {"Where did the energy go? Books since t = 0 (J): stored + losses = inputs",
            "Effects the scene calls for"} <= {
        r.get("ViewBlueprint:display_name", [None])[0] for r in blueprint_rows(path).values()}
    _, statics, _ = readback.read(path)
    assert statics["accuracy/local_error"]["unit"] == "rad, rad/s"
    assert statics["accuracy/substeps"]["unit"] == "1/step"


def test_a_scene_whose_steps_are_not_estimated_shows_no_estimate_and_says_so(tmp_path):
    """Damping far beyond the stability planner's reach: its steps are refused and not
    estimated (NaN); the recording has no estimate series, no empty panes, and says why."""
    scene = load_scene("damped_release").replace(damping=1e9, duration=0.05)
    assert math.isnan(Simulator(scene).error_estimate)
    path = tmp_path / "unestimated.rrd"
    record(scene, path)
    columns = read_back(path)
    assert "accuracy/substeps" in columns
    assert not {"accuracy/local_error", "accuracy/accumulated_error"} & set(columns)
    assert any(text.startswith("scene damped_release start") and "no error estimate" in text
               for text in columns["events"]["TextLog:text"])
    views = blueprint_tree(path)["views"]
    queries = [query for query, _, _ in views.values() if query]
    assert ["accuracy/local_error"] not in queries and ["accuracy/substeps"] in queries
    assert any("no error estimate" in name for name in views)


def test_dopri5_says_its_rtol_and_atol_hold_the_error_and_shows_no_sub_steps(tmp_path):
    """An embedded pair adapts its own step: what holds its error is rtol and atol, in the
    start line, the local error pane and arm-sim run's text alike; it has no sub-steps to
    count, so no sub-steps series or pane."""
    scene = load_scene("damped_release").replace(integrator="dopri5", duration=0.1)
    path = tmp_path / "dopri5.rrd"
    record(scene, path)
    held = f"rtol {scene.rtol:g}, atol {scene.atol:g} (dopri5)"
    assert readouts.held_by(scene) == held
    columns = read_back(path)
    assert "accuracy/local_error" in columns and "accuracy/substeps" not in columns
    (start,) = [t for t in columns["events"]["TextLog:text"] if t.startswith("scene ")]
    assert held in start and "tolerance" not in start
    views = blueprint_tree(path)["views"]
    assert [name for name in views if name.startswith("Local error")][0].endswith(held)
    assert not [name for name in views if "ub-steps" in name]
    assert ["accuracy/substeps"] not in [query for query, _, _ in views.values()]


def residual_titles(path) -> list[str]:
    """The residual pane's title in each blueprint the recording holds."""
    reader, titles = rr.chunk.RrdReader(str(path)), []
    for store in reader.blueprints():
        for chunk in reader.stream(store=store):
            batch = chunk.to_record_batch()
            if "ViewBlueprint:display_name" in batch.schema.names:
                titles += [v[0] for v in batch.column("ViewBlueprint:display_name").to_pylist()
                           if v and v[0].startswith("Energy balance residual")]
    return titles


def test_a_new_simulator_with_another_e0_gets_a_residual_title_with_its_own(tmp_path):
    """The same effects from another initial state: the trust view's residual title names
    the new run's E(0), in a blueprint sent for it."""
    first = Simulator(load_scene("release"))
    second = Simulator(load_scene("release").replace(initial_positions=(0.3, 0.2)))
    path = tmp_path / "two_runs.rrd"
    recorder = telemetry.make_recorder(first.scene, path=str(path))
    for sim in (first, second):
        recorder.start(sim)
        for _ in range(5):
            sim.step()
            recorder.step(sim)
    recorder.finish(second)
    assert first.initial_energy != second.initial_energy
    assert sorted(title.partition("E(0) = ")[2] for title in residual_titles(path)) == [
        f"{sim.initial_energy:.6g} J)" for sim in (first, second)]
