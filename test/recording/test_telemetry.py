"""Rerun recordings read back and compared with the core, value for value.

Each test writes a recording, reads it with rr.chunk.RrdReader and checks it against a
Simulator run of the same scene: entity set, time column, values to 1e-12. What the core
says a row holds (Row) comes from Simulator.sample() and each effect's own scalar
stored_energy, never from the recorder's vectorised readouts.
"""
import math
import socket
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
import rerun as rr

from arm_sim_ros.tools import cli
from arm_sim_ros.physics import model
from arm_sim_ros.recording.rrd import blueprint, readback, sinks, telemetry, writer
from arm_sim_ros.recording import readouts
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.node import core as node_core
from arm_sim_ros.node.params import parameters as node_params

from physics.test_error_estimate import spin   # 100 rad/s about the shoulder, gravity off

TOL = 1e-12
# Every scene's entities; each effect adds its own (SCENES), and an absent one adds none.
ALWAYS = {"energy/total", "energy/balance_residual", "books/stored/kinetic", "joints/angle",
          "joints/velocity", "arm/links", "arm/joints", "arm/tip_trace", "events",
          "accuracy/substeps"}
# ...and where the simulator estimates its steps' error (NaN: it does not):
LOCAL, ACCUMULATED, SUBSTEPS = ("accuracy/local_error", "accuracy/accumulated_error",
                                "accuracy/substeps")
ESTIMATES = {LOCAL, ACCUMULATED}
GRAVITY, WORK, TORQUE = "books/stored/gravity", "books/input/work", "joints/torque"
KINETIC = "books/stored/kinetic"   # T − T₀: T itself for a scene that starts at rest
WINDINGS = {"books/stored/windings", "books/transfer/work", "books/input/electrical_input",
            "books/loss/copper_loss", "joints/current", TORQUE}
SCENES = {  # scene: the entities its effects add
    "release": {GRAVITY},
    "damped_release": {GRAVITY, "books/loss/dissipated"},
    "shoulder_torque_no_gravity": {WORK, TORQUE},
    "per_joint_damping": {GRAVITY, "books/loss/dissipated"},
    "springs_oscillation": {"books/stored/springs"},
    "payload_release": {GRAVITY, "books/input/payload_exchange"},
    "geared_release": {GRAVITY},
    "motor_windings_hold": {GRAVITY} | WINDINGS,
    "effort_limited_hold": {GRAVITY, WORK, TORQUE},
    "wrong_payload_model": {GRAVITY, WORK, TORQUE, "books/input/payload_exchange"},
    "geared_arm": {GRAVITY, "books/loss/dissipated", "books/input/payload_exchange",
                   "joints/commanded_torque", "books/loss/friction_loss",
                   "books/stored/joint_limits"} | WINDINGS,
}
EFFECT_PRESETS = ["per_joint_damping", "springs_oscillation", "payload_release",
                  "geared_release", "motor_windings_hold", "effort_limited_hold",
                  "wrong_payload_model", "geared_arm"]


def read_back(path):
    """{entity: {column: [values in sim_time order]}} of the recording's temporal rows."""
    reader = rr.chunk.RrdReader(str(path))
    (recording,) = reader.recordings()
    columns = defaultdict(lambda: defaultdict(list))
    for chunk in reader.stream(store=recording):
        if chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        for field in batch.schema:
            if field.name in ("rerun.controls.RowId", "log_tick"):
                continue
            column = batch.column(field.name)
            if pa.types.is_duration(column.type) or pa.types.is_timestamp(column.type):
                column = column.cast(pa.int64())
            values = column.to_pylist()
            if field.name.startswith("TextLog:") or field.name == "LineStrips2D:strips" and (
                    chunk.entity_path == "/arm/tip_trace"):
                values = [v[0] for v in values]     # one text / one segment per row
            columns[chunk.entity_path.lstrip("/")][field.name] += values
    for entity in columns.values():
        order = np.argsort(entity["sim_time"], kind="stable")
        for name in entity:
            entity[name] = [entity[name][i] for i in order]
    return columns


def blueprint_rows(path):
    """{blueprint entity: {column: first value}} of the saved blueprint."""
    reader = rr.chunk.RrdReader(str(path))
    (store,) = reader.blueprints()
    rows = defaultdict(dict)
    for chunk in reader.stream(store=store):
        batch = chunk.to_record_batch()
        for field in batch.schema:
            if ":" in field.name:
                rows[chunk.entity_path][field.name] = batch.column(field.name).to_pylist()[0]
    return rows


def stored_parts(sim, state) -> dict:
    """E at `state` split into kinetic and each storing effect's part, from the core's
    scalar functions (model.kinetic_energy, each effect's stored_energy)."""
    q, qd, extra = state[0:2], state[2:4], state[4:4 + len(sim.extra)]
    parts = {"kinetic": model.kinetic_energy(sim.arm, q, qd)}
    for effect in sim.dynamics.active:
        if readouts.stores_energy(effect):
            own = tuple(extra[sim.extra.index(name)] for name in effect.state)
            parts[readouts.STORED_PARTS.get(effect.name, effect.name)] = effect.stored_energy(
                sim.arm, q, own)
    return parts


class Row:
    """The core's sample at one step, and every readout the recording should hold there
    ({entity path: values}); `start`: E(0)'s parts, which the books count changes from."""

    def __init__(self, sim, start):
        s = self.sample = sim.sample()
        kinds = dict(zip(sim.channels, sim.dynamics.channel_kinds))
        self.values = {
            "energy/total": [s.total], "energy/balance_residual": [s.residual],
            "joints/angle": list(s.q), "joints/velocity": list(s.qd)}
        for part, value in stored_parts(sim, sim.state).items():
            self.values[f"books/stored/{part}"] = [value - start[part]]
        for name, value in s.channels.items():     # every channel by name
            self.values[f"books/{kinds[name]}/{name}"] = [value]
        if any(effect.drives for effect in sim.dynamics.active):
            self.values["joints/torque"] = list(s.tau)
        if sim.extra:
            self.values["joints/current"] = [s.extra["i1"], s.extra["i2"]]

    def __getattr__(self, name):
        return getattr(self.sample, name)


class Core:
    """A Simulator's rows as the recording should hold them: take() after each step,
    restart() after a reset (the books count from the new E(0))."""

    def __init__(self, sim):
        self.sim, self.rows = sim, []
        self.restart()

    def restart(self):
        self.start = stored_parts(self.sim, self.sim.state)
        self.take()

    def take(self, *_):
        self.rows.append(Row(self.sim, self.start))


def record(scene, path, steps=None, on_step=None, **options):
    """Run `scene` for `steps` (default: its duration) with a recorder; return the core's
    rows of the same run (initial row included) and the recorder."""
    sim = Simulator(scene)
    recorder = telemetry.make_recorder(scene, path=str(path), **options)
    recorder.start(sim)
    core = Core(sim)
    for k in range(scene.steps_for(scene.duration) if steps is None else steps):
        if on_step is not None:
            on_step(sim, k)
        sim.step()
        recorder.step(sim)
        core.take()
    recorder.finish(sim)
    return core.rows, recorder


def scalars(entity):
    return np.array(entity["Scalars:scalars"])


def assert_equals_core(columns, rows):
    """Every readout the core has is recorded, at simulated time, equal to 1e-12 (of its
    magnitude, for the tens of joules a motor burns)."""
    for path in set().union(*(row.values for row in rows)):
        held = [row for row in rows if path in row.values]   # a grasp adds a channel mid-run
        assert path in columns, path
        assert columns[path]["sim_time"] == [round(row.t * 1e9) for row in held], path
        expected = np.array([row.values[path] for row in held])
        error = np.abs(scalars(columns[path]) - expected)
        assert np.all(error <= TOL * np.maximum(1.0, np.abs(expected))), (path, error.max())


def test_damped_release_reads_back_equal_to_the_core(tmp_path):
    scene = load_scene("damped_release")
    samples, _ = record(scene, tmp_path / "damped.rrd")
    columns = read_back(tmp_path / "damped.rrd")
    assert len(samples) == 201
    assert columns[KINETIC]["sim_time"][-1] == 2_000_000_000   # 2 s of simulated time
    assert_equals_core(columns, samples)
    # Damping takes energy out: total falls while dissipated rises, residual stays tiny.
    total, dissipated = scalars(columns["energy/total"]), scalars(columns["books/loss/dissipated"])
    assert total[-1, 0] < -6.0 and dissipated[-1, 0] > 6.0
    assert np.max(np.abs(scalars(columns["energy/balance_residual"]))) < 1e-5


def commands_for(scene):
    """For the command policies: a new held command every 25 steps, large enough to meet
    geared_arm's effort and voltage limits; None for the others."""
    if not scene.policy.startswith("command"):
        return None

    def commands(sim, k):
        if k % 25 == 0:
            sim.set_command(30.0 * math.sin(k / 40.0), -25.0 + k / 10.0)
    return commands


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """name -> (rows, columns, path) of a recording of that scene (at most 0.3 s), made
    once for the module's tests."""
    made = {}

    def get(name):
        if name not in made:
            scene = load_scene(name)
            scene = scene.replace(duration=min(scene.duration, 0.3))
            path = tmp_path_factory.mktemp("scenes") / f"{name}.rrd"
            rows, _ = record(scene, path, on_step=commands_for(scene))
            made[name] = rows, read_back(path), path
        return made[name]
    return get


@pytest.mark.parametrize("name", sorted(SCENES))
def test_every_effect_records_its_channels_by_name_equal_to_the_core(recordings, name):
    """Each channel by name (J), each stored energy, the winding currents (A) and the
    torque the joints receive, row for row as the Simulator has them; an effect the scene
    lacks has no entity (no copper loss without windings, no dissipation without damping)."""
    rows, columns, _ = recordings(name)
    # (the 3D arm, arm3d/*, is test_recording_story.py's)
    estimates = ESTIMATES if not math.isnan(Simulator(load_scene(name)).error_estimate) else set()
    assert {e for e in columns if not e.startswith("arm3d/")} == ALWAYS | SCENES[name] | estimates
    assert_equals_core(columns, rows)
    sim = Simulator(load_scene(name))
    for channel in sim.channels:     # by name, whatever its kind
        assert sum(p.endswith(f"/{channel}") and p.startswith("books/") for p in columns) == 1


@pytest.mark.parametrize("name", sorted(SCENES))
def test_the_books_view_sums_to_the_residual(recordings, name):
    """'Where did the energy go': Σ stored changes − Σ inputs + Σ losses = the residual,
    row by row, over exactly the series the saved view shows."""
    rows, columns, path = recordings(name)
    (shown,) = [r["ViewContents:query"] for r in blueprint_rows(path).values()
                if "energy/balance_residual" in r.get("ViewContents:query", [])
                and len(r["ViewContents:query"]) > 1]   # (the trust view shows it alone)
    sign = {"stored": 1.0, "loss": 1.0, "input": -1.0}
    kinds = {p: p.split("/")[1] for p in shown if p.startswith("books/")}
    assert set(kinds.values()) <= set(sign)          # transfers are not in the books
    assert {p for p in columns if p.startswith("books/") and "/transfer/" not in p} == set(kinds)
    total = sum(sign[kind] * scalars(columns[p])[:, 0] for p, kind in kinds.items())
    residual = scalars(columns["energy/balance_residual"])[:, 0]
    scale = max(1.0, max(np.max(np.abs(scalars(columns[p]))) for p in kinds))
    assert np.max(np.abs(total - residual)) <= TOL * scale
    # ...and the residual is the core's: E(t) − E(0) − inputs + losses.
    assert np.allclose(residual, [row.residual for row in rows], atol=TOL * scale, rtol=0)


@pytest.mark.parametrize("name, overrides", [
    ("moving_gravity_compensation", {}),
    ("moving_frozen_gravity", {}),
    ("shoulder_torque_no_gravity", {"damping": 0.3}),
    ("release", {"policy": "command", "damping": 0.2}),
    ("release", {"policy": "command_gravity_compensation"}),
    ("release", {"policy": "command_gravity_compensation", "gravity": 0.0}),
])
def test_torque_and_work_equal_the_core_for_every_policy(tmp_path, name, overrides):
    scene = load_scene(name).replace(duration=0.5, **overrides)

    def commands(sim, k):  # a new held command every 10 steps, as a node would get them
        if k % 10 == 0:
            sim.set_command(math.sin(k / 7.0), -0.5 + k / 100.0)

    samples, _ = record(scene, tmp_path / "policy.rrd", on_step=commands)
    columns = read_back(tmp_path / "policy.rrd")
    assert {WORK, TORQUE} <= set(columns)
    assert_equals_core(columns, samples)
    assert np.max(np.abs(scalars(columns[WORK]))) > 0.0


def test_blueprint_is_saved_paused_on_simulated_time(tmp_path):
    record(load_scene("release"), tmp_path / "release.rrd")
    rows = blueprint_rows(tmp_path / "release.rrd")
    names = {r.get("ViewBlueprint:display_name", [None])[0] for r in rows.values()}
    assert {"Energy E = kinetic + gravity (J)", "Events", "Effects the scene calls for",
            "Joint angle (rad)", "Joint velocity (rad/s)"} <= names
    assert any(name.startswith("Arm") for name in names if name)
    assert any(name.startswith("Where did the energy go?") and "(J)" in name
               for name in names if name)
    assert not {"Joint torque received (N m)", "Joint winding current (A)"} & names
    assert rows["/time_panel"]["TimePanelBlueprint:timeline"] == ["sim_time"]
    assert rows["/time_panel"]["TimePanelBlueprint:play_state"] == [1]     # paused
    queries = [r["ViewContents:query"] for r in rows.values() if "ViewContents:query" in r]
    assert ["energy/total"] in queries
    # no damping, no actuator here: the books are T, V and the residual
    assert ["books/stored/kinetic", "books/stored/gravity", "energy/balance_residual"] in queries


def test_series_are_named_and_coloured(tmp_path):
    record(load_scene("damped_release").replace(duration=0.1), tmp_path / "styled.rrd")
    reader = rr.chunk.RrdReader(str(tmp_path / "styled.rrd"))
    styles = {}
    for chunk in reader.stream(store=reader.recordings()[0]):
        batch = chunk.to_record_batch()
        if chunk.is_static and "SeriesLines:names" in batch.schema.names:
            styles[chunk.entity_path.lstrip("/")] = (batch.column("SeriesLines:names")[0].as_py(),
                                                     batch.column("SeriesLines:colors")[0].as_py())
    assert set(styles) == {"energy/total", "energy/balance_residual", KINETIC, GRAVITY,
                           "books/loss/dissipated", "joints/angle", "joints/velocity",
                           LOCAL, ACCUMULATED, SUBSTEPS}
    assert styles["books/loss/dissipated"][0] == ["loss: damping ∫d·q̇²dt"]
    assert styles["energy/total"][0] == ["total E = kinetic + gravity"]
    for names, colors in styles.values():
        assert all(names) and len(names) == len(colors)
        for rgba in colors:   # visible on the dark theme: no channel darker than mid grey
            assert max((rgba >> 24) & 255, (rgba >> 16) & 255, (rgba >> 8) & 255) >= 128


def test_series_names_use_only_glyphs_the_viewer_can_draw():
    """The viewer's font lacks e.g. ᵀ, and a missing glyph crashes it (seen in 0.41)."""
    drawn = set("∫τ·²₀−") | {"\u0307"}      # each seen rendered in a headless screenshot
    ascii_ = {chr(c) for c in range(32, 127)}
    assert blueprint.DRAWN <= drawn
    names = [n for title, series in blueprint.JOINT_SERIES.values() for n in (title, *series)]
    for name in SCENES:
        sim = Simulator(load_scene(name))
        snap = readouts.Snapshot(sim)
        styled = blueprint.series(snap)       # a style for each readout, none for another
        assert set(styled) == set(readouts.channel_values(snap, np.array([sim.state]),
                                                          np.zeros((1, 2)))) | set(
            readouts.accuracy_paths(snap))
        names += [n for series, _, _ in styled.values() for n in series]
        names += [blueprint.joint_series(p)[0] for p in blueprint.joint_paths(snap)]
        names += blueprint.effects_document(snap).splitlines()
    for name in names:
        assert set(name) <= drawn | ascii_, name
    assert blueprint.drawable("E = q̇ᵀMq̇/2, Ø 43.5 mm") == "E = q̇TMq̇/2, ? 43.5 mm"


def test_arm_drawing_is_the_models_arm_y_up_and_the_view_flips_it(tmp_path):
    scene = load_scene("release").replace(step_size=0.001, duration=0.1,
                                          link_lengths=(0.8, 1.2), com_distances=(0.4, 0.5))
    samples, _ = record(scene, tmp_path / "drawn.rrd")
    columns = read_back(tmp_path / "drawn.rrd")
    every = round(writer.FRAME_PERIOD / scene.step_size)
    frames = samples[::every]
    assert columns["arm/links"]["sim_time"] == [round(s.t * 1e9) for s in frames]
    for sample, strips, joints in zip(frames, columns["arm/links"]["LineStrips2D:strips"],
                                      columns["arm/joints"]["Points2D:positions"]):
        base, elbow, tip = (np.array(p) for p in model.link_points(scene.arm, sample.q))
        # Rerun stores 2D positions as float32.
        assert np.allclose(np.array(strips), [[base, elbow], [elbow, tip]], atol=2e-7, rtol=0)
        assert np.allclose(np.array(joints), [base, elbow, tip], atol=2e-7, rtol=0)
    # The trace joins consecutive tips.
    trace = np.array(columns["arm/tip_trace"]["LineStrips2D:strips"])
    assert np.allclose(trace[1:, 0], trace[:-1, 1], atol=0, rtol=0)


def test_events_are_logged_at_the_latest_simulated_time(tmp_path):
    scene = load_scene("release").replace(duration=0.1)
    sim = Simulator(scene)
    recorder = telemetry.make_recorder(scene, path=str(tmp_path / "events.rrd"))
    recorder.start(sim)
    for _ in range(7):
        sim.step()
        recorder.step(sim)
    recorder.event("refused command: tau1 = nan is not finite", level="warn")
    recorder.finish(sim)
    events = read_back(tmp_path / "events.rrd")["events"]
    assert events["TextLog:text"][0].startswith("scene release start: policy zero")
    assert events["TextLog:text"][1] == "refused command: tau1 = nan is not finite"
    assert events["TextLog:level"] == ["INFO", "WARN"]
    assert events["sim_time"] == [0, round(7 * 0.01 * 1e9)]


def test_the_simulators_stability_interventions_reach_the_text_log(tmp_path):
    stiff = load_scene("damped_release").replace(damping=300.0, duration=0.05)
    wild = load_scene("release").replace(initial_velocities=(5e153, 5e153), duration=0.05)
    for scene, kind, level in ((stiff, "substepping", "WARN"), (wild, "fault", "ERROR")):
        samples, _ = record(scene, tmp_path / f"{kind}.rrd")
        columns = read_back(tmp_path / f"{kind}.rrd")
        lines = [(text, lvl) for text, lvl in zip(columns["events"]["TextLog:text"],
                                                  columns["events"]["TextLog:level"])
                 if text.startswith(kind)]
        assert len(lines) == 1 and lines[0][1] == level
        assert np.all(np.isfinite(scalars(columns["joints/velocity"])))   # held, finite
        assert len(columns["joints/angle"]["sim_time"]) == len(samples)


def test_after_a_reset_the_timeline_runs_on_like_the_nodes_stamps(tmp_path):
    scene = load_scene("damped_release")
    sim = Simulator(scene)
    recorder = telemetry.make_recorder(scene, path=str(tmp_path / "reset.rrd"))
    recorder.start(sim)
    samples = [sim.sample()]
    for steps in (30, 20):
        for _ in range(steps):
            sim.step()
            recorder.step(sim)
            samples.append(sim.sample())
        sim.reset()
        recorder.start(sim)
        samples.append(sim.sample())
    recorder.finish(sim)
    columns = read_back(tmp_path / "reset.rrd")
    kinetic = columns[KINETIC]
    h_ns = round(0.01 * 1e9)
    # Each run starts where the last ended (the reset shows as one instant with two rows).
    assert kinetic["sim_time"] == ([k * h_ns for k in range(31)] + [k * h_ns for k in range(30, 51)]
                                   + [50 * h_ns])
    assert np.max(np.abs(scalars(kinetic)[:, 0] - [s.kinetic for s in samples])) <= TOL
    starts = [t for t, text in zip(columns["events"]["sim_time"], columns["events"]["TextLog:text"])
              if "start" in text]
    assert starts == [0, 30 * h_ns, 50 * h_ns]
    trace = np.array(columns["arm/tip_trace"]["LineStrips2D:strips"])
    assert np.allclose(trace[31][0], trace[31][1])   # the trace breaks at the reset


def test_a_new_simulator_is_recorded_with_its_own_parameters(tmp_path):
    """The node may swap in a rebuilt Simulator (changed parameters) without start()."""
    first = Simulator(load_scene("release"))
    second = Simulator(load_scene("release").replace(damping=0.7, gravity=3.0))
    recorder = telemetry.make_recorder(first.scene, path=str(tmp_path / "swap.rrd"))
    recorder.start(first)
    samples = [first.sample()]
    for sim in (first, second):
        for _ in range(25):
            sim.step()
            recorder.step(sim)
            samples.append(sim.sample())
    recorder.finish(second)
    columns = read_back(tmp_path / "swap.rrd")
    assert np.max(np.abs(scalars(columns["energy/total"])[:, 0]
                         - [s.total for s in samples])) <= TOL
    assert len(columns["books/loss/dissipated"]["sim_time"]) == 25


def test_batches_sent_along_the_way_read_back_the_same(tmp_path, monkeypatch):
    monkeypatch.setattr(telemetry, "BATCH_STEPS", 37)
    monkeypatch.setattr(telemetry, "CHECK_EVERY", 5)
    monkeypatch.setattr(telemetry, "FILE_PERIOD", 1e9)
    scene = load_scene("damped_release").replace(step_size=0.002, duration=0.5)
    sends = []
    original = writer.BatchWriter.send
    monkeypatch.setattr(writer.BatchWriter, "send",
                        lambda self, snap, runs, states, *rest: (
                            sends.append(sum(steps for _, _, steps in runs)),
                            original(self, snap, runs, states, *rest)))
    samples, _ = record(scene, tmp_path / "batched.rrd")
    assert sends == [37] * 6 + [251 - 37 * 6]
    columns = read_back(tmp_path / "batched.rrd")
    assert_equals_core(columns, samples)
    trace = np.array(columns["arm/tip_trace"]["LineStrips2D:strips"])
    assert np.allclose(trace[1:, 0], trace[:-1, 1], atol=0, rtol=0)   # no gap between batches


def test_an_unwritable_file_is_one_warning_and_the_run_goes_on(tmp_path):
    warnings = []
    scene = load_scene("damped_release")
    sim = Simulator(scene)
    recorder = telemetry.make_recorder(scene, path=str(tmp_path / "missing" / "x.rrd"),
                                       warn=warnings.append)
    recorder.start(sim)
    sim.run(scene.duration, recorder.step)
    recorder.event("still running")
    recorder.finish(sim)
    assert sim.steps == 200
    assert len(warnings) == 1 and "cannot write" in warnings[0]
    assert not recorder.enabled


def test_a_missing_viewer_is_one_warning_and_the_run_goes_on(tmp_path):
    with socket.socket() as s:       # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    warnings = []
    scene = load_scene("release")
    samples, recorder = record(scene, tmp_path / "alongside.rrd", connect=f"127.0.0.1:{port}",
                               warn=warnings.append)
    assert len(warnings) == 1 and f"127.0.0.1:{port}" in warnings[0]
    assert recorder.sinks == [f"file {tmp_path / 'alongside.rrd'}"]
    assert_equals_core(read_back(tmp_path / "alongside.rrd"), samples)   # the file still works


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the display check is Linux's")
def test_spawning_without_a_display_is_one_warning(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    warnings = []
    scene = load_scene("release")
    sim = Simulator(scene)
    recorder = telemetry.make_recorder(scene, spawn=True, warn=warnings.append)
    recorder.start(sim)
    sim.run(scene.duration, recorder.step)
    recorder.finish(sim)
    assert len(warnings) == 1 and "no display" in warnings[0]
    assert recorder.sinks == [] and sim.steps == 50


def test_viewer_addresses():
    assert sinks.viewer_url("9876") == "rerun+http://127.0.0.1:9876/proxy"
    assert sinks.viewer_url("host:1234") == "rerun+http://host:1234/proxy"
    assert sinks.viewer_url("rerun+http://h:1/proxy") == "rerun+http://h:1/proxy"
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        url = sinks.viewer_url(str(server.getsockname()[1]))
        assert sinks.viewer_reachable(url)
    assert not sinks.viewer_reachable(url)


def test_vectorised_drawing_equals_the_models_link_points():
    arm = model.ArmParameters(link_lengths=(0.7, 1.3), link_masses=(2.0, 0.5),
                              com_distances=(0.3, 0.9), com_inertias=(0.05, 0.2))
    q1, q2 = np.random.default_rng(4).uniform(-7.0, 7.0, size=(2, 500))
    elbow, tip = readouts.drawing_points(arm, q1, q2)
    for i in range(500):
        _, (ex, ey), (tx, ty) = model.link_points(arm, (q1[i], q2[i]))
        assert np.allclose([*elbow[i], *tip[i]], [ex, ey, tx, ty], atol=TOL, rtol=0)


@pytest.mark.parametrize("name", EFFECT_PRESETS + ["release", "moving_gravity_compensation"])
def test_readouts_energies_and_torque_equal_the_simulators(name):
    """readouts.energies = Simulator.energies (kinetic with the rotors' armature; stored:
    gravity with the payload folded in, springs, inductors) and Snapshot.joint_torque =
    Simulator.joint_torque (after effort limits and windings), row for row over a run that
    starts moving (q̇ = (0.8, −1.1) rad/s), so every term counts."""
    scene = load_scene(name)
    scene = scene.replace(duration=min(scene.duration, 0.3), initial_velocities=(0.8, -1.1))
    sim, commands = Simulator(scene), commands_for(scene) or (lambda sim, k: None)
    snap = readouts.Snapshot(sim)
    states, held = [sim.state], [tuple(sim.dynamics.command)]
    for k in range(scene.steps_for(scene.duration)):
        commands(sim, k)
        sim.step()
        states.append(sim.state)
        held.append(tuple(sim.dynamics.command))
    rows = np.array(states)
    kinetic, stored = readouts.energies(snap, rows)
    torque = snap.joint_torque(rows, np.array(held)) if snap.drives else None
    for i, state in enumerate(states):
        core_kinetic, core_stored = sim.energies(state)
        scale = max(1.0, abs(core_kinetic), abs(core_stored))
        assert abs(kinetic[i] - core_kinetic) <= TOL * scale
        assert abs(sum(v[i] for v in stored.values()) - core_stored) <= TOL * scale
        assert abs(kinetic[i] + sum(v[i] for v in stored.values()) - sim.energy(state)) <= TOL * scale
        if torque is not None:
            sim.dynamics.command[:] = held[i]
            assert np.allclose(torque[i], sim.joint_torque(state), atol=TOL, rtol=TOL)
    assert set(stored) == set(stored_parts(sim, states[0])) - {"kinetic"}
    if "motors" in sim.dynamics.effects and any(sim.arm.armature):   # the rotors count in T
        bare = readouts.energies(readouts.Snapshot(Simulator(scene.replace(motors=None))), rows)[0]
        assert np.all(kinetic[1:] > bare[1:])


def effects_document(path):
    """The recording's static effects document: (text, media type)."""
    document = readback.read(path)[1][blueprint.EFFECTS_PATH]
    return document["TextDocument:text"], document["TextDocument:media_type"]


@pytest.mark.parametrize("name, rows, absent", [
    ("geared_arm", ["| gravity | magnitude along −y | 9.81 | m/s² |",
                    "| actuator | policy | command_gravity_compensation |  |",
                    "| effort_limits | limit per joint | 40, 20 | N m |",
                    "| motors | gear_ratio | 100, 50 |  |",
                    "|  | resistance | 0.573, 0.573 | ohm |",
                    "|  | inductance | 0.000301, 0.000301 | H |",
                    "|  | torque_constant | 0.0404, 0.0404 | N m/A |",
                    "|  | voltage_limit | 24, 24 | V |",
                    "|  | armature N²J | 0.181, 0.04525 | kg m² |",
                    "| damping | d | 0.05 | N m s/rad |",
                    "| payload | mass | 0.3 | kg |",
                    "- E: kinetic + gravity + windings + joint_limits",
                    "- inputs: electrical_input, payload_exchange",
                    "- losses: copper_loss, dissipated, friction_loss",
                    "- extra state: i1, i2 (A)"], ["springs", "controller_model"]),
    ("springs_oscillation", ["| springs | stiffness | 20, 5 | N m/rad |",
                             "|  | rest_positions | 0.5, -0.5 | rad |", "- E: kinetic + springs"],
     ["| gravity", "| damping", "| actuator", "- inputs", "- losses"]),
    ("wrong_payload_model", ["| controller_model | payload_mass | 0 | kg |",
                             "| payload | mass | 0.5 | kg |"], ["motors"]),
    ("per_joint_damping", ["| damping | d per joint | 0.5, 0.05 | N m s/rad |"], ["actuator"]),
])
def test_the_effects_the_scene_calls_for_are_one_static_markdown_document(recordings, name,
                                                                           rows, absent):
    _, columns, path = recordings(name)
    text, media_type = effects_document(path)
    assert media_type == "text/markdown"
    assert blueprint.EFFECTS_PATH not in columns          # static: logged once, no timeline
    lines = text.splitlines()
    effects = Simulator(load_scene(name)).dynamics.effects
    listed = [line.split("|")[1].strip() for line in lines if line.startswith("| ")]
    assert [e for e in listed if e and e != "effect"] == list(effects)
    for row in rows:
        assert row in lines, row
    for word in absent:
        assert word not in text
    views = blueprint_rows(path)
    assert any(r.get("ViewBlueprint:class_identifier") == ["TextDocument"] for r in views.values())


def test_a_payload_grasped_mid_run_keeps_the_books_and_reads_each_row_as_taken(tmp_path):
    """Simulator.set_payload rebuilds the dynamics (a payload_exchange channel appears): the
    rows before read with the old layout, those after with the new, and the books keep
    counting from the run's E(0), so they still sum to the residual."""
    scene = load_scene("damped_release").replace(duration=0.4)
    path = tmp_path / "grasp.rrd"
    rows, _ = record(scene, path, on_step=lambda sim, k: k == 20 and sim.set_payload(0.5))
    columns = read_back(path)
    assert_equals_core(columns, rows)
    exchange = columns["books/input/payload_exchange"]
    assert exchange["sim_time"][0] == round(0.21 * 1e9) and len(exchange["sim_time"]) == 20
    assert abs(scalars(exchange)[0, 0]) > 0.01          # the grasp took energy: booked
    books = scalars(columns[KINETIC])[:, 0] + scalars(columns[GRAVITY])[:, 0] \
        + scalars(columns["books/loss/dissipated"])[:, 0]
    books[21:] -= scalars(exchange)[:, 0]
    assert np.max(np.abs(books - scalars(columns["energy/balance_residual"])[:, 0])) <= TOL


def test_a_channel_removed_mid_run_keeps_its_booked_energy_in_the_residual(tmp_path):
    """Damping set to 0 while it runs (the node's live `damping`) removes the dissipated
    channel; the loss already booked stays in the residual, as in the simulator's."""
    scene = load_scene("damped_release").replace(duration=0.4)
    path = tmp_path / "undamped.rrd"
    rows, _ = record(scene, path, on_step=lambda sim, k: k == 20 and sim.change_scene(
        sim.scene.replace(damping=0.0)))
    columns = read_back(path)
    assert_equals_core(columns, rows)
    residual = scalars(columns["energy/balance_residual"])[:, 0]
    assert len(residual) == 41 and np.max(np.abs(residual)) < 1e-5


def test_the_recording_verifies(tmp_path):
    viewer = Path(rr.__file__).parent.parent / "rerun_cli" / "rerun"
    if not viewer.is_file():
        pytest.skip("the rerun CLI is not shipped with this rerun-sdk install")
    record(load_scene("damped_release"), tmp_path / "verify.rrd")
    result = subprocess.run([str(viewer), "rrd", "verify", str(tmp_path / "verify.rrd")],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr


def test_arm_sim_run_writes_the_recording(tmp_path, capsys):
    path = tmp_path / "cli.rrd"
    assert cli.main(["run", "--scene", "damped_release", "--rerun", str(path), "--json"]) == 0
    columns = read_back(path)
    core = Core(Simulator(load_scene("damped_release")))
    core.sim.run(2.0, core.take)
    assert_equals_core(columns, core.rows)
    assert "books/loss/dissipated" in columns and WORK not in columns


def test_arm_sim_run_refuses_an_unwritable_recording_before_running(tmp_path, capsys):
    """One rule for every output (as --csv and --bag): refused up front, exit 2, one line."""
    path = tmp_path / "no" / "such" / "dir.rrd"
    assert cli.main(["run", "--scene", "release", "--rerun", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.strip().splitlines()) == 1 and "does not exist" in err


class Log:
    def __init__(self):
        self.lines = []

    def __getattr__(self, level):
        return lambda text: self.lines.append((level, text))


def run_node(config, ticks, command=None):
    """Tick an in-process node beside a Simulator of its scene, sending command(k) before
    tick k if given; return its log, the core's samples and the recording read back."""
    log = Log()
    core = node_core.ArmSimCore(config, log, wall_clock=lambda: 0.0, start_stamp_ns=0)
    reference = Core(Simulator(config.scene))
    for k in range(ticks):
        if command is not None:
            core.on_command(command(k))
            reference.sim.set_command(*command(k))
        core.tick(0.0)
        for _ in range(config.steps_per_tick):
            reference.sim.step()
            reference.take()
    core.finish()
    return log, reference.rows, read_back(config.values["rerun_path"])


def test_the_node_writes_a_recording_in_process(tmp_path):
    path = tmp_path / "node.rrd"
    config = node_params.resolve_parameters({"scene": "damped_release", "rerun_path": str(path),
                                           "publish_rate": 50.0})
    log, samples, columns = run_node(config, ticks=25)
    assert_equals_core(columns, samples)
    assert columns[KINETIC]["sim_time"][-1] == round(0.5 * 1e9)
    assert any("start" in text for text in columns["events"]["TextLog:text"])
    assert not [text for level, text in log.lines if level in ("warning", "error")]


def test_the_node_records_each_ticks_command_with_its_steps(tmp_path):
    """The node hands over a tick's states at once (step_batch); a command taken between
    ticks holds for the next tick's steps, as in the core."""
    path = tmp_path / "commanded.rrd"
    config = node_params.resolve_parameters({
        "scene": "release", "policy": "command_gravity_compensation", "damping": 0.2,
        "rerun_path": str(path), "publish_rate": 20.0, "command_timeout": 0.0})
    _, samples, columns = run_node(config, ticks=12,
                                   command=lambda k: [math.sin(k), 0.3 * k - 1.0])
    assert config.steps_per_tick == 5
    assert {WORK, TORQUE, "books/loss/dissipated"} <= set(columns)
    assert_equals_core(columns, samples)


class StepSpy:
    """A recorder with the per-step protocol only: step(sim) after every step."""

    def __init__(self):
        self.seen = []

    def start(self, sim):
        self.seen.append(sim.steps)

    def step(self, sim):
        self.seen.append(sim.steps)

    def finish(self, sim):
        pass


class BatchSpy(StepSpy):
    """A recorder with step_batch: the states of many steps in one call."""

    books_every = 3

    def step_batch(self, sim, states, books=()):
        self.seen += range(sim.steps - len(states) + 1, sim.steps + 1)
        self.states = getattr(self, "states", []) + list(states)
        self.books = getattr(self, "books", []) + list(books)


def test_arm_sim_runs_loop_gives_every_step_to_either_protocol(monkeypatch):
    monkeypatch.setattr(cli, "RUN_BATCH_STEPS", 7)
    scene = load_scene("damped_release").replace(duration=0.5)
    sim, per_step, batched = Simulator(scene), StepSpy(), BatchSpy()
    for recorder in (per_step, batched):
        recorder.start(sim)
    drift = cli.run_recorded(sim, 0.5, [per_step, batched])
    reference = Simulator(scene)
    states, books = [], []
    assert drift == reference.run(0.5, lambda s: (states.append(s.state), books.extend(
        (s.steps, s.error_estimate, s.accumulated_error, s.substeps_taken))))
    assert per_step.seen == batched.seen == list(range(51))
    assert batched.states == states
    # every books_every-th step's error books, as the simulator had them after it
    assert batched.books == [v for k in range(3, 51, 3) for v in books[4 * k - 4:4 * k]]
    assert cli.run_recorded(sim, 0.0, [batched]) == 0.0 and len(batched.seen) == 51


def test_the_node_at_one_step_a_tick_records_every_step_events_and_reset_in_order(tmp_path):
    """The node collects steps over ticks (RECORD_EVERY) before handing them over; an event,
    a new command, a reset and a hold each hand over what was collected first, so every
    row, command and text line lands at its own step."""
    path = tmp_path / "ticks.rrd"
    config = node_params.resolve_parameters({"scene": "release", "rerun_path": str(path),
                                           "command_timeout": 0.0})
    assert config.steps_per_tick == 1
    core = node_core.ArmSimCore(config, Log(), wall_clock=lambda: 0.0, start_stamp_ns=0)
    reference = Simulator(config.scene)
    kinetic, torque = [reference.sample().kinetic], [reference.sample().tau]
    for k in range(23):
        if k == 7:
            core.on_command([float("nan"), 0.0])               # an event, between ticks
        if k in (3, 12):
            core.on_command([0.5 * k, -1.0])
            reference.set_command(0.5 * k, -1.0)
        if k == 17:
            core.reset()
            reference.reset()
            kinetic.append(reference.sample().kinetic)
            torque.append(reference.sample().tau)
        core.tick(0.0)
        reference.step()
        kinetic.append(reference.sample().kinetic)
        torque.append(reference.sample().tau)
    core.finish()
    columns = read_back(path)
    h_ns = round(config.scene.step_size * 1e9)
    assert columns[KINETIC]["sim_time"] == (
        [k * h_ns for k in range(18)] + [k * h_ns for k in range(17, 24)])
    assert np.max(np.abs(scalars(columns[KINETIC])[:, 0] - kinetic)) <= TOL
    assert np.max(np.abs(scalars(columns["joints/torque"]) - torque)) <= TOL
    # A line lands on the next step recorded: the refusal after step 7 on step 8; the
    # restart's own line on its initial row, the node's reason on the step after it.
    events = list(zip(columns["events"]["TextLog:text"], columns["events"]["sim_time"]))
    assert ("refused command: tau1 = nan is not finite", 8 * h_ns) in events
    assert [t for text, t in events if text.startswith("scene release start:")] == [0, 17 * h_ns]
    assert ("reset to the scene's initial state", 18 * h_ns) in events


def test_a_node_that_holds_records_the_refused_tick_then_stops(tmp_path):
    path = tmp_path / "held.rrd"
    config = node_params.resolve_parameters({"scene": "release", "rerun_path": str(path),
                                           "initial_velocities": [5e153, 5e153]})
    core = node_core.ArmSimCore(config, Log(), wall_clock=lambda: 0.0, start_stamp_ns=0)
    for _ in range(4):
        core.tick(0.0)
    core.finish()
    assert core.held
    columns = read_back(path)
    # The start and the refused step (the last finite state, held), each at its own time.
    assert columns["joints/angle"]["sim_time"] == [0, round(config.scene.step_size * 1e9)]
    assert np.all(np.isfinite(scalars(columns["joints/velocity"])))
    assert any(text.startswith("integration not finite")
               for text in columns["events"]["TextLog:text"])


def test_a_live_parameter_change_keeps_the_nodes_timeline_and_books(tmp_path):
    """A payload grasped and the damping changed while the node runs (live parameters):
    the recording goes on at the next step, on the JointState stamps, and its books keep
    counting from the run's E(0), so they still sum to the residual."""
    path, origin = tmp_path / "live.rrd", 1_763_900_000_123_456_789
    config = node_params.resolve_parameters({
        "scene": "damped_release", "initial_positions": [0.7, 0.3],
        "initial_velocities": [1.0, -0.5], "rerun_path": str(path), "publish_rate": 50.0})
    core = node_core.ArmSimCore(config, Log(), wall_clock=lambda: 0.0, start_stamp_ns=origin)
    published = []
    for k in range(30):
        if k == 10:
            core.set_parameters({"payload.mass": 0.5})
        if k == 20:
            core.set_parameters({"damping": 0.3})
        published.append(core.tick(0.0))
    core.finish()
    columns = read_back(path)
    h_ns = round(config.scene.step_size * 1e9)
    angle = columns["joints/angle"]
    assert angle["sim_time"] == [k * h_ns for k in range(61)]         # no jump, no repeat
    assert angle["ros_time"] == [origin + t for t in angle["sim_time"]]
    rows = dict(zip(angle["ros_time"], angle["Scalars:scalars"]))
    assert all(rows[js.stamp_ns] == js.position for js in published)
    residual = at_times(columns["energy/balance_residual"])
    books = defaultdict(float)
    for entity in columns:
        kind = entity.split("/")[1] if entity.startswith("books/") else None
        for t, value in at_times(columns[entity]).items() if kind else ():
            books[t] += -value if kind == "input" else value
    assert set(books) == set(residual)
    assert max(abs(books[t] - residual[t]) for t in residual) <= TOL
    assert len(columns["books/input/payload_exchange"]["sim_time"]) == 40   # from the grasp on


def at_times(entity) -> dict:
    """{sim_time: the first scalar} of an entity read back."""
    return {t: v[0] for t, v in zip(entity["sim_time"], entity["Scalars:scalars"])}


# --- the error books: how far each step may be off, and what holding it cost -------------

def books_of(scene, steps):
    """{step: (error_estimate, accumulated_error, sub-steps the step took)} of a Simulator
    run; sub-steps: the growth of substeps_taken, which counts split steps only (0: a
    plain step, one sub-step)."""
    sim, out, taken = Simulator(scene), {}, 0
    for _ in range(steps):
        sim.step()
        grown, taken = sim.substeps_taken - taken, sim.substeps_taken
        out[sim.steps] = (sim.error_estimate, sim.accumulated_error, grown or 1)
    return out


@pytest.mark.parametrize("tolerance", [2e-3, 0.0])
def test_every_steps_error_books_are_recorded_as_the_simulator_has_them(tmp_path, tolerance):
    """recorder.step(sim) after every step: each step's local error estimate, the sum of
    them and the sub-steps it took, at its own simulated time, exactly."""
    scene = spin(0.01, tolerance=tolerance, duration=0.5)   # 2e-3 splits its steps
    record(scene, tmp_path / "spin.rrd")
    columns, expected = read_back(tmp_path / "spin.rrd"), books_of(scene, 50)
    for path, k in ((LOCAL, 0), (ACCUMULATED, 1), (SUBSTEPS, 2)):
        assert columns[path]["sim_time"] == [s * 10_000_000 for s in range(1, 51)], path
        assert scalars(columns[path])[:, 0].tolist() == [expected[s][k] for s in range(1, 51)]
    substeps = scalars(columns[SUBSTEPS])[:, 0]
    if tolerance:        # the spin's steps are split to meet 2e-3 per s
        assert substeps.max() > 1
    else:                # estimate only: plain steps, each with a larger error
        assert set(substeps) == {1.0}
        split = books_of(spin(0.01, tolerance=2e-3), 50)
        assert scalars(columns[LOCAL]).max() > max(v[0] for v in split.values())


def test_arm_sim_run_samples_the_error_books_every_few_steps_exactly(tmp_path, capsys):
    """arm-sim run hands steps over in batches: the books of every BOOKS_EVERY-th step and
    of each batch's last, as the simulator had them; a sample's sub-steps stand for the
    steps since the one before: exact where the count held, between its values where it
    changed."""
    path = tmp_path / "spin.rrd"
    assert cli.main(["run", "--set", "initial_positions=0,0.5", "--set", "gravity=0",
                     "--set", "initial_velocities=100,0", "--set", "tolerance=0.002",
                     "--duration", "1", "--rerun", str(path)]) == 0
    capsys.readouterr()
    columns, expected = read_back(path), books_of(spin(0.01, tolerance=2e-3), 100)
    steps = [round(t / 10_000_000) for t in columns[LOCAL]["sim_time"]]
    every = telemetry.BOOKS_EVERY
    assert set(range(every, 101, every)) <= set(steps) and steps[-1] == 100
    assert len(steps) < 100                                   # sampled, not every step
    for entity, k in ((LOCAL, 0), (ACCUMULATED, 1)):
        assert columns[entity]["sim_time"] == columns[LOCAL]["sim_time"]
        assert scalars(columns[entity])[:, 0].tolist() == [expected[s][k] for s in steps]
    before, split = 0, 0
    for step, value in zip(steps, scalars(columns[SUBSTEPS])[:, 0]):
        span = [expected[s][2] for s in range(before + 1, step + 1)]
        assert min(span) <= value <= max(span), (step, value, span)
        if min(span) == max(span):
            assert value == span[0]
        split += value > 1
        before = step
    assert split > len(steps) // 2


def test_the_node_records_its_error_books_and_each_ticks_sub_steps(tmp_path):
    """The node samples the books as arm-sim run does; a tick's sub-steps are its steps':
    exactly steps x the count while it holds (a fast spin under a tolerance)."""
    path = tmp_path / "spin_node.rrd"
    config = node_params.resolve_parameters({
        "scene": "release", "gravity": 0.0, "initial_positions": [0.0, 0.5],
        "initial_velocities": [100.0, 0.0], "tolerance": 2e-3, "step_size": 0.002,
        "publish_rate": 100.0, "rerun_path": str(path)})
    assert config.steps_per_tick == 5
    run_node(config, ticks=30)
    columns = read_back(path)
    expected = books_of(config.scene, 150)
    steps = [round(t / 2_000_000) for t in columns[LOCAL]["sim_time"]]
    assert set(range(telemetry.BOOKS_EVERY, 151, telemetry.BOOKS_EVERY)) <= set(steps)
    assert scalars(columns[ACCUMULATED])[:, 0].tolist() == [expected[s][1] for s in steps]
    ticks = scalars(columns["node/substeps"])[:, 0]
    assert len(ticks) == 30
    every = telemetry.BOOKS_EVERY   # a tick's sub-steps are spread over the books samples
    for k, value in enumerate(ticks):
        first, last = every * (5 * k // every) + 1, every * -(-(5 * k + 5) // every)
        near = [expected[s][2] for s in range(first, min(last, 150) + 1)]
        own = [expected[s][2] for s in range(5 * k + 1, 5 * k + 6)]
        if min(near) == max(near):
            assert value == sum(own), k
        assert 5 * min(near) <= value <= 5 * max(near), k
    assert ticks[-1] >= 5 * 2                     # the tolerance splits every step


def test_arm_sim_runs_simulator_events_land_on_the_step_they_came_in(tmp_path, capsys):
    """arm-sim run hands a chunk of steps over after taking them; an event from inside the
    chunk (a joint limit's switch, sub-stepping) still lands on its own step, the one after
    event.t, beside the series it explains."""
    path = tmp_path / "impact.rrd"
    assert cli.main(["run", "--scene", "limit_impact", "--duration", "1.5",
                     "--rerun", str(path)]) == 0
    capsys.readouterr()
    reference = Simulator(load_scene("limit_impact"))
    reference.run(1.5)
    h = reference.step_size
    expected = [(round(e.t / h + 1) * round(h * 1e9), f"{e.kind}: {e.message}")
                for e in reference.events]
    assert len(expected) > 3 and expected[0][0] > 0.5e9        # inside later chunks
    events = read_back(path)["events"]
    assert [(t, text) for t, text in zip(events["sim_time"], events["TextLog:text"])
            if not text.startswith("scene ")] == expected
