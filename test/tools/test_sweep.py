"""`arm-sim sweep` and `arm_sim_ros.sweep`: the table is the same bytes on one process, two
processes, blocks in any order and a re-run; a sample that diverges or cannot be built is a
row with its reason; the table, its sidecar, its picture and the summary are written."""
import csv
import io
import json
import random

import numpy as np
import pytest

import arm_sim_ros
from arm_sim_ros.physics.metrics import NAMES
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.tools import cli
from arm_sim_ros.tools.sweep import pool, table
from arm_sim_ros.tools.sweep.api import make_sweep
from arm_sim_ros.tools.sweep.rows import run_task

# a servo with noisy sensors: a payload grid, friction and a sensor seed drawn per sample
SERVO = dict(scene="servo_reach", duration=0.05,
             vary={"payload.mass": "0.2,1.0", "friction.coulomb": "uniform:0.0:0.5",
                   "sensors.seed": "integers:0:4294967295",
                   "sensors.position_noise": "1e-4,1e-4"}, samples=3, seed=11)


@pytest.fixture(autouse=True)
def pure_python(monkeypatch):
    monkeypatch.setenv("ARM_SIM_COMPILED", "0")       # compiling is not what these test


def test_the_table_is_the_same_bytes_on_one_or_two_processes_in_any_order_and_again():
    once = arm_sim_ros.sweep(**SERVO, workers=1)
    assert once.complete and once.counts["ok"] == 6
    assert arm_sim_ros.sweep(**SERVO, workers=1).text == once.text
    two = arm_sim_ros.sweep(**SERVO, workers=2)        # asked for: processes, however little
    assert two.text == once.text and two.workers == "2 local processes"
    sweep = make_sweep(load_scene("servo_reach"), SERVO["vary"], 3, 11, duration=0.05)
    tasks = sweep.tasks()
    assert len(tasks) == 6                             # blocks of one: order can matter
    random.Random(3).shuffle(tasks)
    lines = {row[0]: table.line(row) for task in tasks for row in run_task(task).rows}
    assert table.text(sweep.columns, lines) == once.text


def test_each_row_holds_its_keys_state_books_figures_and_outcome():
    result = arm_sim_ros.sweep(**SERVO, workers=1)
    rows = list(csv.DictReader(io.StringIO(result.text)))
    assert [int(r["index"]) for r in rows] == list(range(6))
    assert [float(r["payload.mass"]) for r in rows] == [0.2] * 3 + [1.0] * 3
    assert list(rows[0])[:6] == ["index", "payload.mass", "friction.coulomb", "sensors.seed",
                                 "sensors.position_noise[0]", "sensors.position_noise[1]"]
    assert set(rows[0]) >= {"status", "q_1", "q_2", "qd_1", "qd_2", "steps", "substeps",
                            "max_abs_residual", "accumulated_error", "reason",
                            *(f"{n}_{j}" for n in NAMES for j in (1, 2))}
    for row in rows:
        assert row["status"] == "ok" and row["reason"] == ""
        assert int(row["steps"]) == 50 and row["accumulated_error"] == ""   # estimate off
        assert 0 <= int(row["sensors.seed"]) < 2 ** 32
        assert float(row["peak_torque_1"]) > 0 and float(row["tracking_error_1"]) > 0
    assert len({r["sensors.seed"] for r in rows}) == 6


def test_a_sample_that_diverges_or_cannot_be_built_is_a_row_with_its_reason():
    result = arm_sim_ros.sweep("springs_oscillation", {"integrator": "rk4,euler",
                                                       "springs.stiffness": "1000",
                                                       "payload.mass": "normal:0:1"},
                               samples=4, seed=1, duration=0.05, workers=1)
    status, reason = result.columns["status"], result.columns["reason"]
    mass = result.columns["payload.mass"]
    refused = [k for k in range(8) if mass[k] < 0]
    assert refused and all(status[k] == "refused" and "payload.mass" in reason[k]
                           for k in refused)
    for k in range(8):
        if k in refused:
            assert np.isnan(result.columns["q_1"][k])
        elif k < 4:
            assert status[k] == "ok" and reason[k] == ""
        else:                                          # euler: no stable step for springs
            assert status[k] in ("diverged", "fault") and "diverged" in reason[k]
    # no figures without a set-point, but peak torque: what the springs do is no servo's
    assert np.isnan(result.columns["settle_time_1"]).all()


def test_the_command_writes_the_table_its_sidecar_and_picture_and_prints_a_summary(
        capsys, tmp_path):
    out = tmp_path / "servo.csv"
    argv = ["sweep", "servo_reach", "--vary", "payload.mass=lin:0.2:1:2", "--vary",
            "friction.coulomb=0;0.2", "--duration", "0.05", "--workers", "1", "-o", str(out)]
    assert cli.main(argv) == 0
    said = capsys.readouterr().out
    assert "4 samples (grid 2 x 2)" in said and "ok 4, diverged 0, refused 0, fault 0" in said
    assert "samples/s" in said and "settle_time_1 (s)" not in said   # 50 ms: none settles
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 4 and rows[3]["payload.mass"] == "1.0"
    sidecar = json.loads(out.with_suffix(".json").read_text())
    assert sidecar["complete"] and sidecar["rows"] == 4 and sidecar["runs"][0]["wall_seconds"] > 0
    assert sidecar["sweep"]["vary"] == ["payload.mass=lin:0.2:1:2", "friction.coulomb=0;0.2"]
    assert out.with_suffix(".png").stat().st_size > 10_000
    assert cli.main(argv) == 2 and "exists already" in capsys.readouterr().err
    assert cli.main(argv + ["--force"]) == 0


def test_the_estimate_is_a_column_when_asked_for():
    result = arm_sim_ros.sweep("release", {"gravity": "9.81"}, duration=0.05, workers=1,
                               estimate="global")
    assert result.columns["accumulated_error"][0] > 0


def test_scheduler_without_dask_is_one_line_naming_the_extra(capsys, tmp_path, monkeypatch):
    monkeypatch.setitem(__import__("sys").modules, "distributed", None)
    code = cli.main(["sweep", "release", "--vary", "gravity=1,2", "--duration", "0.01",
                     "--scheduler", "tcp://127.0.0.1:1", "-o", str(tmp_path / "x.csv")])
    err = capsys.readouterr().err
    assert code == 2 and "arm_sim_ros[fit]" in err and err.count("\n") == 1, err


def test_the_time_left_is_paced_by_the_blocks_own_work_a_first_compile_left_out(monkeypatch):
    """Blocks run in worker processes; each says how long it took and how much of that was
    compiling. The progress is paced by the work alone: a first block that spent 8 of its
    10 s compiling counts 2 s."""
    from dataclasses import replace

    from arm_sim_ros.tools.sweep import run
    sweep = make_sweep(load_scene(), ["gravity=1;2;3"], duration=0.01)
    blocks = [run_task(task) for task in sweep.tasks()]
    timed = [replace(b, seconds=10.0 if k == 0 else 2.0, compiling=8.0 if k == 0 else 0.0)
             for k, b in enumerate(blocks)]
    monkeypatch.setattr(pool, "here", lambda tasks, stop: iter(timed))

    class Seen:
        def __init__(self):
            self.paced, self.done = [], []

        def measured(self, seconds):
            self.paced.append(seconds)

        def update(self, done):
            self.done.append(done)

    seen = Seen()
    result = run.execute(sweep, progress=seen)
    assert result.complete and result.compiling == 8.0
    assert seen.paced == [2.0, 4.0, 6.0] and seen.done == [1, 2, 3]
    from arm_sim_ros.tools.progress import Progress
    progress = Progress(3, "arm-sim sweep", unit="samples", clock=lambda: 100.0)
    progress.measured(2.0)                       # one sample's work took 2 s: two more, 4 s
    progress.done = 1
    assert progress.left(100.0) == "about 4 s left"


def test_a_small_sweep_stays_in_its_process_a_long_one_spreads(monkeypatch):
    """Starting processes costs seconds: by default the first block runs here, and the
    rest go to processes (one per core) only where they would take longer than that here."""
    small = arm_sim_ros.sweep("release", {"gravity": "1;2;3"}, duration=0.01)
    assert small.workers == "this process" and small.complete
    monkeypatch.setattr(pool, "SPAWN_WORTH", 0.0)
    monkeypatch.setattr("os.cpu_count", lambda: 2)
    spread = arm_sim_ros.sweep("release", {"gravity": "1;2;3"}, duration=0.01)
    assert spread.workers == "2 local processes" and spread.text == small.text
