"""The pytest plugin (arm_sim_ros/testing/plugin.py), installed with the package: a user's
test file, run by pytest in a directory of its own, gets the fixtures with no import, and a
failing test's report names its trace, recording and plot, which are there to open."""
import csv
import subprocess
import sys
from importlib.metadata import entry_points

USER_TEST = '''
import numpy as np

TARGET = np.array([0.5, -0.3])


def pd(reading):
    return 20.0 * (TARGET - reading.q) - 2.0 * reading.qd


def test_reaches_target_without_overshoot(arm):
    trace = arm.run(pd, "release", seconds=1.0, overrides={"gravity": 0.0},
                    reference=TARGET)
    assert trace.overshoot() < 0.001, "too much overshoot"
'''


def test_the_plugin_is_installed_with_the_package():
    assert "arm_sim_ros.testing.plugin" in {
        e.value for e in entry_points(group="pytest11") if e.name == "arm_sim_ros"}


def test_a_failing_controller_test_names_its_trace_recording_and_plot(tmp_path):
    (tmp_path / "test_user.py").write_text(USER_TEST)
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                          "--basetemp", str(tmp_path / "base"), "test_user.py"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert run.returncode == 1, run.stdout + run.stderr
    out = run.stdout
    assert "too much overshoot" in out and "arm_sim evidence" in out
    paths = {line.split(": ", 1)[0].strip(): line.split(": ", 1)[1].strip()
             for line in out.splitlines() if line.strip().startswith(("csv:", "png:", "rrd:"))}
    assert set(paths) == {"csv", "png", "rrd"}
    with open(paths["csv"]) as file:
        rows = list(csv.reader(file))
    assert rows[0][:5] == ["t", "q1", "q2", "qd1", "qd2"] and len(rows) == 1 + 101
    assert open(paths["png"], "rb").read(8) == b"\x89PNG\r\n\x1a\n"
    from arm_sim_ros.recording.rrd.readback import read
    temporal = read(paths["rrd"])[2]
    assert {"joints/angle", "joints/reference", "joints/torque", "energy/residual"} <= set(temporal)
