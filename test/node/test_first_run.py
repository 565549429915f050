"""The first thing a newcomer runs is clean: the default scene (release, a double pendulum,
as `scripts/run` starts it) logs no warning. The tolerance taking more sub-steps is said at
info, and the chaos that makes its motion unpredictable past a time is said once, at info,
in plain words. Warnings stay for faults: a tolerance not met at the cap, a motion lost by
steps too coarse for it."""
import pytest

from tools.test_no_surprises import ListLog
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
        "local error 3.39e-05 per s (scaled) for tolerance 5e-05 (aiming at half): each 0.01 s "
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
