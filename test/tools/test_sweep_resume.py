"""Nothing lost: a real SIGINT to `arm-sim sweep` writes the samples done and says how to
go on; `--resume` runs the rest, and the table is byte for byte the uninterrupted one's. A
resume refuses a table another sweep wrote."""
import os
import signal
import subprocess
import sys
import time

import arm_sim_ros
from arm_sim_ros.tools import cli

ARM_SIM = [sys.executable, "-m", "arm_sim_ros.tools.cli"]
SAMPLES = 60
VARY = ["friction.coulomb=uniform:0:0.5", "payload.mass=0.2;1.0"]
ARGS = ["sweep", "servo_reach", "--vary", VARY[0], "--vary", VARY[1], "--samples",
        str(SAMPLES // 2), "--seed", "5", "--duration", "0.2"]


def test_ctrl_c_keeps_the_samples_done_and_resume_gives_the_uninterrupted_table(
        tmp_path, monkeypatch):
    monkeypatch.setenv("ARM_SIM_COMPILED", "0")       # compiling is not what this tests
    env = dict(os.environ)
    out = tmp_path / "sweep.csv"
    process = subprocess.Popen([*ARM_SIM, *ARGS, "--workers", "2", "-o", str(out)], env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    deadline = time.monotonic() + 120            # a loaded machine spawns slowly
    while time.monotonic() < deadline and process.poll() is None and (
            not out.exists() or out.read_text().count("\n") < 2):
        time.sleep(0.05)                         # the first block is written at once
    os.killpg(process.pid, signal.SIGINT)        # as Ctrl-C does: the whole process group,
    stdout, stderr = process.communicate(timeout=120)   # workers starting up included
    assert process.returncode == 130, stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr
    kept = out.read_text().count("\n") - 1
    assert 1 <= kept < SAMPLES, stdout
    assert "interrupted (SIGINT)" in stderr and "--resume" in stderr
    assert f"of {SAMPLES} samples are in" in stderr

    resumed = subprocess.run([*ARM_SIM, *ARGS, "--workers", "1", "--resume", "-o", str(out)],
                             env=env, capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert f"{SAMPLES - kept} samples run" in resumed.stdout
    whole = arm_sim_ros.sweep("servo_reach", VARY, samples=SAMPLES // 2, seed=5, duration=0.2,
                              workers=1)
    assert out.read_text() == whole.text


def test_resume_refuses_another_sweeps_table(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("ARM_SIM_COMPILED", "0")
    out = str(tmp_path / "sweep.csv")
    base = ["sweep", "release", "--vary", "gravity=1;2", "--duration", "0.01", "--workers", "1"]
    assert cli.main([*base, "-o", out]) == 0
    capsys.readouterr()
    assert cli.main([*base, "--seed", "1", "--resume", "-o", out]) == 2
    err = capsys.readouterr().err
    assert "written by another sweep (its seed differ)" in err and err.count("\n") == 1
    assert cli.main([*base, "--resume", "-o", out]) == 0          # the same: nothing to run
    assert "0 samples run" in capsys.readouterr().out
