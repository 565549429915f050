"""How `arm-sim run` ends, said honestly: strict JSON, a fault exits 1, a signal (SIGINT,
SIGTERM, SIGHUP) closes every output at the same last step and exits 130, a closed pipe
is quiet, and every output follows one rule (refused if it exists, unless --force).
"""
import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader

from arm_sim_ros.outputs import check_output
from arm_sim_ros.physics.scene import preset_names
from arm_sim_ros.tools import cli
from arm_sim_ros.tools.progress import Progress
from arm_sim_ros.usage import UsageError

ARM_SIM = [sys.executable, "-m", "arm_sim_ros.tools.cli"]


def strict_json(text):
    """RFC 8259: no NaN, no Infinity."""
    def refuse(constant):
        raise ValueError(f"{constant} is not JSON")
    return json.loads(text, parse_constant=refuse)


@pytest.mark.parametrize("overrides", [
    ["--set", "initial_velocities=5e153,0"],           # a stage's velocity products overflow
    ["--set", "initial_velocities=5e153,5e153"],        # the first step is not finite
])
def test_json_is_strict_and_a_faulted_run_exits_1(capsys, overrides):
    code = cli.main(["run", *overrides, "--duration", "0.05", "--json"])
    out, err = capsys.readouterr()
    result = strict_json(out)
    assert code == 1
    assert result["fault"] and result["refused_steps"] > 0 and result["interrupted_at"] is None
    assert "arm-sim: fault" in err


def test_a_clean_run_reports_no_fault_and_exits_0(capsys):
    assert cli.main(["run", "--json"]) == 0
    result = strict_json(capsys.readouterr().out)
    assert result["fault"] is None and result["refused_steps"] == 0 and result["interrupted_at"] is None


@pytest.mark.parametrize("signal_name", ["SIGINT", "SIGTERM", "SIGHUP"])
def test_a_signal_closes_every_output_at_the_same_last_step(tmp_path, signal_name):
    outputs = {"--csv": tmp_path / "run.csv", "--bag": tmp_path / "bag", "--rerun": tmp_path / "run.rrd"}
    process = subprocess.Popen(
        [*ARM_SIM, "run", "--duration", "1000", "--json",
         *(str(x) for option, path in outputs.items() for x in (option, path))],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60              # a loaded machine imports slowly
    while time.monotonic() < deadline and (not outputs["--csv"].exists()
                                           or outputs["--csv"].stat().st_size < 10_000):
        time.sleep(0.1)                             # signal only once the run is under way
    started = time.monotonic()
    process.send_signal(getattr(signal, signal_name))
    out, err = process.communicate(timeout=30)
    assert time.monotonic() - started < 20.0         # a hang guard, not a timing
    assert process.returncode == 130, err
    assert "Traceback" not in err and f"interrupted ({signal_name}) at t = " in err
    result = strict_json(out)
    last = result["interrupted_at"]
    assert 0 < last < 1000 and result["t"] == last
    with open(outputs["--csv"]) as stream:
        assert float(list(csv.reader(stream))[-1][0]) == last
    with AnyReader([outputs["--bag"]]) as bag:
        stamps = [t for _, t, _ in bag.messages()]
    assert max(stamps) - min(stamps) == round(last * 1e9)   # bag time from the run's start
    from recording.test_telemetry import read_back
    assert max(read_back(outputs["--rerun"])["energy/total"]["sim_time"]) == round(last * 1e9)


# `arm-sim run` with the stability plan's cap on sub-steps raised, so that one step of an
# engaged compliant limit with damping 1e8 takes minutes (the cap bounds a step to ~2 s on
# an idle machine); it says on stderr when its stop handler is in, and when the second
# step starts (the first taken whole, kernels loaded).
SLOW_STEP_RUN = [sys.executable, "-c", """
import sys
from arm_sim_ros.physics.stepping import stability
from arm_sim_ros.tools import cli, signals
stability.MAX_SUBSTEPS = 10 ** 9
enter = signals.StopOnSignals.__enter__
def noted(self):
    print("stop handler in", file=sys.stderr, flush=True)
    return enter(self)
signals.StopOnSignals.__enter__ = noted
from arm_sim_ros.physics.simulator import Simulator
step = Simulator.step
def told(self):
    if self.steps == 1:
        print("second step starts", file=sys.stderr, flush=True)
    step(self)
Simulator.step = told
sys.exit(cli.main(sys.argv[1:]))
""", "run", "--scene", "compliant_limit", "--set", "joint_limits.damping=1e8",
                 "--set", "initial_positions=0.1,1.95", "--set", "initial_velocities=0,3"]


@pytest.mark.parametrize("signal_name", ["SIGTERM", "SIGINT"])
def test_one_signal_stops_a_step_of_minutes_at_the_last_whole_step(tmp_path, signal_name):
    """The elbow reaches its compliant stop in the second step, which would take minutes:
    one signal abandons it, and the CSV and the JSON end at the first."""
    rows = tmp_path / "run.csv"
    process = subprocess.Popen([*SLOW_STEP_RUN, "--duration", "1", "--json", "--csv", str(rows)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert process.stderr.readline() == "stop handler in\n"
        assert process.stderr.readline() == "second step starts\n"
        process.send_signal(getattr(signal, signal_name))
        out, err = process.communicate(timeout=30)  # a hang guard: the step takes minutes
    finally:
        process.kill()
    assert process.returncode == 130, err
    assert "Traceback" not in err and f"interrupted ({signal_name}) at t = 0.010000 s" in err
    result = strict_json(out)
    assert result["interrupted_at"] == result["t"] == 0.01
    with open(rows) as stream:
        table = list(csv.reader(stream))
    assert [float(row[0]) for row in table[1:]] == [0.0, 0.01]
    assert float(table[-1][1]) == result["q"][0] and float(table[-1][2]) == result["q"][1]


@pytest.mark.parametrize("command", [["run"], ["run", "--csv", "/dev/stdout", "--duration", "5"],
                                     ["scenes"]])
def test_a_reader_that_goes_away_ends_the_run_quietly(command):
    process = subprocess.Popen([*ARM_SIM, *command], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE)
    process.stdout.readline()
    process.stdout.close()                      # as `| head -1` does
    err = process.stderr.read().decode()
    process.wait(timeout=30)
    assert "Traceback" not in err and "BrokenPipe" not in err


@pytest.mark.parametrize("option, name", [("--csv", "a.csv"), ("--rerun", "a.rrd"), ("--bag", "bag")])
def test_every_output_refuses_what_exists_and_force_replaces_it(tmp_path, capsys, option, name):
    path = tmp_path / name
    assert cli.main(["run", option, str(path)]) == 0
    capsys.readouterr()
    assert cli.main(["run", option, str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "exists already" in err and "--force" in err
    assert cli.main(["run", option, str(path), "--force", "--duration", "0.1"]) == 0


def test_force_replaces_a_symlink_never_its_target(tmp_path, capsys):
    target = tmp_path / "precious.txt"
    target.write_text("keep me")
    link = tmp_path / "run.csv"
    link.symlink_to(target)
    assert cli.main(["run", "--csv", str(link)]) == 2
    assert cli.main(["run", "--csv", str(link), "--force"]) == 0
    assert target.read_text() == "keep me" and not link.is_symlink()


def test_force_replaces_only_a_bag_directory(tmp_path):
    folder = tmp_path / "notes"
    folder.mkdir()
    (folder / "thesis.tex").write_text("years of work")
    with pytest.raises(UsageError, match="holds more than a bag's files"):
        check_output(str(folder), "--bag", force=True, directory=True)


def test_an_unwritable_directory_is_refused_before_the_work(tmp_path):
    if os.geteuid() == 0:
        pytest.skip("root writes anywhere")
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    with pytest.raises(UsageError, match="is not writable"):
        check_output(str(locked / "a.csv"), "--csv")


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


class Stream(list):
    def write(self, text):
        self.append(text)

    def flush(self):
        pass

    def isatty(self):
        return False


def test_progress_is_silent_for_short_work_and_a_plain_line_off_a_terminal():
    clock, stream = Clock(), Stream()
    progress = Progress(100.0, "arm-sim run release", stream=stream, clock=clock)
    clock.now = 1.0
    progress.update(50.0)
    assert stream == []                                  # done within a couple of seconds
    clock.now = 12.0
    progress.update(60.0)
    line = "".join(stream)
    assert line.startswith("arm-sim run release: 60 of 100 s (60.0 %), about 8 s left")
    assert "\r" not in line


@pytest.mark.parametrize("argv", [
    ["--set", "initial_velocities=1000,-1000", "--duration", "2"],   # unstable at h = 0.01 s
    ["--step", "10", "--duration", "20"],                            # a step far too large
])
def test_a_run_that_diverged_while_finite_says_so_and_exits_1(capsys, argv):
    # tolerance 0: the default tolerance (physics/trust/accuracy.py) would split these steps
    # until they are accurate, and nothing would diverge
    code = cli.main(["run", *argv, "--set", "tolerance=0", "--json"])
    out, err = capsys.readouterr()
    result = strict_json(out)
    assert code == 1 and "diverged" in result["fault"] and "diverged" in err
    assert err.count("arm-sim: fault") == 1                   # said once, not every step
    # what is reported is the last sound state, not the nonsense that followed
    assert max(abs(v) for v in result["q"] + result["qd"]) < 1e4
    assert abs(result["residual"]) < 1.0 + abs(result["total"])


@pytest.mark.parametrize("scene", sorted(preset_names()))
def test_no_preset_trips_the_divergence_guard(capsys, scene):
    assert cli.main(["run", "--scene", scene, "--duration", "5", "--json"]) == 0
    assert strict_json(capsys.readouterr().out)["fault"] is None


def test_a_step_abandoned_midway_leaves_the_simulator_as_the_step_before_left_it():
    """Stopped inside a sub-stepped step of a compliant stop (its error books, switch counts
    and shadow half done), the simulator is put back at the step before: state, books,
    counts and events as those of a run that ended there."""
    from arm_sim_ros.physics.scene import load_scene
    from arm_sim_ros.physics.simulator import Simulator
    from arm_sim_ros.tools.signals import StopOnSignals
    from arm_sim_ros.tools.run.whole_steps import WholeSteps

    scene = load_scene("compliant_limit").replace(initial_positions=(0.1, 1.95),
                                                  initial_velocities=(0.0, 3.0))
    sim, reference = Simulator(scene), Simulator(scene)
    real, calls, seen, at = sim.switching.step, [0], [], []

    def sub_step(*args):                  # the switching stepper's integrator step
        calls[0] += 1
        if calls[0] == 400:               # inside step 90 in pure Python, taken as 131
            at.append(sim.steps)          # sub-steps (later where steps in one mode are
            signal.raise_signal(signal.SIGTERM)   # compiled calls)
        return real(*args)

    sim.switching.step = sub_step
    with StopOnSignals() as stop:
        WholeSteps(sim, stop).run(300, lambda s: seen.append((s.steps, calls[0])))
    assert stop.requested == "SIGTERM"
    assert sim.steps == seen[-1][0] == at[0] >= 90 and seen[-1][1] < 400
    for _ in range(sim.steps):
        reference.step()
    assert sim.state == reference.state and sim.substeps_taken == reference.substeps_taken
    assert sim.error_estimate == reference.error_estimate
    assert sim.accumulated_error == reference.accumulated_error
    assert sim.switch_events == reference.switch_events and list(sim.events) == list(reference.events)


@pytest.mark.parametrize("ending, code", [("sys.exit(0)", -signal.SIGINT), ("exit_as_main(0)", 0)])
def test_a_stop_handled_inside_an_exec_still_exits_with_its_code_under_python_m(tmp_path, ending,
                                                                                 code):
    """`python -m arm_sim_ros.node.main` stopped by SIGTERM during a first compile (numba and
    dataclasses exec strings) died by SIGINT one stop in six: CPython notes a KeyboardInterrupt
    that passed through an exec however it was handled. exit_as_main forgets that note."""
    (tmp_path / "stopped_in_exec.py").write_text(
        "import sys\nfrom arm_sim_ros.usage import exit_as_main\n"
        "try:\n    exec('raise KeyboardInterrupt')\nexcept KeyboardInterrupt:\n    pass\n"
        f"{ending}\n", encoding="utf-8")
    done = subprocess.run([sys.executable, "-m", "stopped_in_exec"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=60,
                          env=os.environ | {"PYTHONPATH": str(Path(__file__).resolve().parents[2])})
    assert done.returncode == code, done.stderr
