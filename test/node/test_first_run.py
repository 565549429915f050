"""The first thing a newcomer runs is clean: the default scene (release, a double pendulum,
as `scripts/run` starts it) logs no warning. The tolerance taking more sub-steps is said at
info, and the chaos that makes its motion unpredictable past a time is said once, at info,
in plain words. Warnings stay for faults: a tolerance not met at the cap, a motion lost by
steps too coarse for it."""
import pytest

from tools.test_no_surprises import ListLog
from tools.test_run_endings import Clock
from arm_sim_ros.node.core import ArmSimCore
from arm_sim_ros.node.params.parameters import resolve_parameters
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.reports import LEVELS, Event
from arm_sim_ros.physics.simulator import Simulator


def said(log, level):
    """What a ListLog heard at `level` ("warning": warnings and errors)."""
    return [message for kind, message in log.lines if kind == level]


def run_node(seconds, **parameters):
    log = ListLog()
    core = ArmSimCore(resolve_parameters(parameters), log, wall_clock=lambda: 0.0)
    for _ in range(round(seconds * core.config.values["publish_rate"])):
        core.tick(0.0)
    core.finish()
    return core, log


def test_the_default_scene_is_release_and_its_first_run_logs_no_warning():
    core, log = run_node(10.0)          # scripts/run: the default scene, 10 simulated seconds
    assert core.config.scene.name == "release"
    assert said(log, "warning") == []
    assert [m for m in said(log, "info") if "sub-steps" in m] == [
        "local error 4.03e-05 per s (scaled) for tolerance 5e-05 (aiming at half): each 0.01 s "
        "step is taken as 3 sub-steps (at t = 1.940000 s)"]


def test_its_chaos_is_said_once_at_info_in_plain_words():
    _, log = run_node(20.0)
    assert said(log, "warning") == []
    unpredictable = [m for m in said(log, "info") if "unpredictable" in m]
    assert unpredictable == [
        "past t = 11.73 s this motion is unpredictable: it is chaotic, and errors far below the "
        "tolerance at each step have grown past 1 rad; the run goes on, but no longer follows "
        "the true motion (the error estimate stops at that bound) (at t = 11.720000 s)"]


@pytest.mark.parametrize("overrides, kinds", [
    ({"max_substeps": 1}, ["substepping"]),
    ({"max_substeps": 1, "step_size": 0.05}, ["substepping", "accuracy"]),
], ids=["tolerance not met at the cap", "motion lost by steps too coarse"])
def test_faults_still_warn(overrides, kinds):
    sim = Simulator(load_scene("release").replace(**overrides))
    sim.run(13.0)
    assert [(e.kind, e.level) for e in sim.events] == [(k, "warning") for k in kinds]
    if "accuracy" in kinds:
        assert "the run no longer follows the true motion (a step too coarse for it, or " \
               "chaos)" in sim.events[-1].message


def test_each_kind_of_event_has_one_level_for_every_listener():
    """The node's log, a recording's text log and arm-sim run read the level from the event."""
    assert {kind: Event(0.0, kind, "").level for kind in (
        "switch", "substeps", "unpredictable", "substepping", "accuracy", "saturation",
        "servo", "books", "fault")} == {
        "switch": "info", "substeps": "info", "unpredictable": "info",
        "substepping": "warning", "accuracy": "warning", "saturation": "warning",
        "servo": "warning", "books": "error", "fault": "error"}
    assert set(LEVELS.values()) == {"info", "error"}


# --- what the console says: at start what is on, each second the pace, at the end what was done

def started_line(log):
    return next(m for kind, m in log.lines if kind == "info" and " started: " in m)


def test_the_start_line_of_the_default_scene_names_its_method_and_estimate():
    _, log = run_node(0.1)
    assert started_line(log) == ("scene release started: policy command, h = 0.01 s, rk4, "
                                 "1 steps per tick; estimate global, tolerance 5e-05")


def test_the_start_line_says_what_is_on_and_where_the_truth_goes(tmp_path):
    """With sensors, command_delay, estimate off or lockstep on, the line was the same as
    without: nothing said the readings were no longer the truth."""
    recording = tmp_path / "arm.rrd"
    _, log = run_node(0.1, scene="servo_hold", estimate="off", command_delay=0.002,
                      lockstep=True, rerun_path=str(recording),
                      **{"sensors.position_resolution": [0.006, 0.006],
                         "sensors.velocity": "differences"})
    assert started_line(log) == (
        "scene servo_hold started: policy command_gravity_compensation, h = 0.001 s, rk4, "
        "10 steps per tick; estimate off: no error estimate; sensors (position_resolution "
        "[0.006, 0.006], velocity differences): joint_states carries the readings, "
        "~/true_joint_states the truth; command_delay 0.002 s; lockstep: one tick per "
        f"command, or after 0.1 s without one while a node listens on /clock; recording {recording}")


def test_a_recording_that_could_not_start_is_not_named_as_one(tmp_path, monkeypatch):
    """rerun-sdk absent (the colcon venv beside ROS's numpy): the error line, then a start line
    that said "recording arm.rrd" all the same."""
    from arm_sim_ros.node import core as node_core

    def no_rerun(config, log):
        log.error("Rerun telemetry is off: No module named 'rerun'")
    monkeypatch.setattr(node_core, "make_recorder", no_rerun)
    _, log = run_node(0.05, rerun_path=str(tmp_path / "arm.rrd"))
    assert started_line(log).endswith("; Rerun telemetry off (see the error above)")
    assert "arm.rrd" not in started_line(log)
    assert said(log, "info")[-1].endswith("; no recording; 0 commands refused, 0 late ticks")


def test_the_status_pace_starts_at_the_first_tick_and_the_stop_line_sums_the_run(tmp_path):
    """A first tick that took 3 s (a compile) read "real-time factor 0.00" in the first status
    line; then a duplicate last status line read 0.00 or 1.42. Now the pace counts from the
    first tick done, and the run ends with one line: where, at what pace, what was written."""
    wall, log = Clock(), ListLog()
    wall.now = 100.0
    recording = tmp_path / "arm.rrd"
    core = ArmSimCore(resolve_parameters({"rerun_path": str(recording)}), log, wall_clock=wall)
    assert "real-time factor      -   energy" in core.status_line(0.0)   # no tick yet
    wall.now += 3.0                         # the first tick's compile
    core.tick(wall.now)
    for _ in range(99):                     # then 99 ticks of 10 ms in real time
        wall.now += 0.01
        core.tick(wall.now)
    rtf = core.real_time_factor(wall.now)
    assert abs(rtf - 1.0) < 1e-9
    assert "real-time factor   1.00   energy" in core.status_line(rtf)
    core.on_command([float("nan"), 0.0])    # refused
    wall.now += 0.5
    core.finish()
    assert said(log, "info")[-1] == (
        f"stopped at t = 1.000 s, 0.990 s simulated in 1.49 s since the first tick "
        f"(real-time factor 0.66); wrote {recording}; 1 commands refused, 0 late ticks")
    assert recording.stat().st_size > 0


def test_quiet_prints_no_info_line_and_the_run_ends_with_its_stop_line():
    import os
    import subprocess
    import sys

    env = os.environ | {"ROS_DOMAIN_ID": "209", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    command = [sys.executable, "-m", "arm_sim_ros.node.main", "--transport", "dds",
               "--duration", "0.3", "--ros-args", "-p", "real_time_factor:=0.0"]
    quiet = subprocess.run(command[:7] + ["--quiet"] + command[7:], env=env,
                           capture_output=True, text=True, timeout=120)
    assert quiet.returncode == 0 and quiet.stdout == "" and quiet.stderr == "", quiet.stderr
    loud = subprocess.run(command, env=env, capture_output=True, text=True, timeout=120)
    lines = loud.stderr.strip().splitlines()
    assert loud.returncode == 0 and " started: " in lines[0], loud.stderr
    assert "]: stopped at t = 0.300 s, 0.290 s simulated in " in lines[-1]
    assert lines[-1].endswith("; no recording; 0 commands refused, 0 late ticks")
    assert "real-time factor   0.00" not in loud.stdout
