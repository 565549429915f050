"""Issue 35: the estimate is a choice. Scene key `estimate`: global (the error books: the
shadow and its checks, the default) or off (the steps alone: no shadow, no check, no
tolerance). An off run takes the steps a global run at tolerance 0 takes, bit for bit, and
computes nothing else."""
import math
from types import SimpleNamespace

import pytest

from arm_sim_ros.physics.batch import Batch
from arm_sim_ros.physics.scene import SceneError, load_scene, preset_names
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.physics.trust import accuracy, shadow
from arm_sim_ros.tools.fit.problem import replay_scene


def test_the_estimate_is_global_unless_a_scene_says_off():
    assert load_scene("release").estimate == "global"
    assert load_scene("release").replace(estimate="off", tolerance=0.0).estimate == "off"


def test_estimate_off_alone_sets_the_tolerance_to_0():
    """A scene file, `--set estimate=off` or `-p estimate:=off` that names no tolerance beside
    it means no tolerance: there is no estimate to hold one to."""
    assert load_scene("release").replace(estimate="off").tolerance == 0.0
    assert load_scene("release").with_text_overrides(["estimate=off"]).tolerance == 0.0


def test_estimate_off_with_a_tolerance_named_beside_it_is_refused_in_one_line():
    with pytest.raises(SceneError) as refused:
        load_scene("release").replace(estimate="off", tolerance=1e-6)
    message = str(refused.value)
    assert "\n" not in message
    assert message == ("estimate off computes no error estimate, so it cannot hold tolerance "
                       "= 1e-06: set tolerance 0, or leave it out (estimate off alone sets it "
                       "to 0)")


def test_an_unknown_estimate_is_refused_naming_the_choices():
    with pytest.raises(SceneError, match="estimate 'local' is unknown; choose global .* or off"):
        load_scene("release").replace(estimate="local")


@pytest.mark.parametrize("name", preset_names())
def test_an_off_run_takes_the_steps_of_a_global_run_at_tolerance_0_bit_for_bit(name):
    """At tolerance 0 the books never change a step: off leaves out only what they compute
    (switching scenes too: a switch is located, not estimated)."""
    scene = load_scene(name).replace(tolerance=0.0)
    estimated, off = Simulator(scene), Simulator(scene.replace(estimate="off"))
    for sim in (estimated, off):
        sim.set_command(1.0, -0.5)
    assert estimated.run(0.6) == off.run(0.6)
    assert estimated.state == off.state and estimated.switch_events == off.switch_events
    assert estimated.substeps_taken == off.substeps_taken
    assert math.isnan(off.error_estimate) and math.isnan(off.accumulated_error)


@pytest.mark.parametrize("name", ["release", "stick_slip", "geared_arm", "servo_reach"])
def test_an_off_run_computes_no_shadow_and_no_check(name, monkeypatch):
    """Off pays nothing for what it does not compute: no step is doubled, no shadow is
    followed (the compiled path: ARM_SIM_COMPILED=0 here; test_compiled_off.py there)."""
    monkeypatch.setenv("ARM_SIM_COMPILED", "0")
    called = []
    for owner, method in ((accuracy.Accuracy, "doubled"), (accuracy.Accuracy, "check"),
                          (shadow.Shadow, "follow"), (shadow.Shadow, "land")):
        monkeypatch.setattr(owner, method, lambda *a, m=method, **k: called.append(m))
    sim = Simulator(load_scene(name).replace(estimate="off", tolerance=0.0))
    sim.set_command(2.0, -1.0)
    sim.run(0.5)
    assert called == [] and sim.accuracy.shadow is None
    assert math.isfinite(sim.state[0]) and sim.steps == round(0.5 / sim.step_size)


def test_a_new_command_asks_for_no_check_when_nothing_is_checked():
    sim = Simulator(load_scene("release").replace(estimate="off", tolerance=0.0))
    sim.run(0.1)
    sim.set_command(3.0, 0.0)
    sim.run(0.1)
    assert math.isnan(sim.error_estimate) and sim.fault is None


def test_fit_rollouts_run_with_the_estimate_off():
    sampled = SimpleNamespace(dt=0.01, source="a recording at 100 Hz")   # its sampling only
    scene, substeps = replay_scene(load_scene("damped_release"), "command", sampled)
    assert (scene.estimate, scene.tolerance, substeps) == ("off", 0.0, 1)


def test_a_batch_runs_with_the_estimate_off_and_so_does_its_single_arm_check():
    batch = Batch(load_scene("release"), count=3)
    assert (batch.scene.estimate, batch.scene.tolerance) == ("off", 0.0)
    batch.run(50)
    sim = Simulator(batch.scene)
    for _ in range(50):
        sim.step()
    assert [float(column[0]) for column in batch.state[:4]] == list(sim.state[:4])
