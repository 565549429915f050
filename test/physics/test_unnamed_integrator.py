"""Issue 35: a scene that names no integrator gets one that needs no stability sub-steps for
its motor windings: exponential_rk4 where they are stiff at its step, rk4 elsewhere (the
same bits: the explainer's figures stay as they are, test_explainer.py). A named method
that needs sub-steps where another of ours would need none is told which."""
import pytest

from arm_sim_ros.physics.scene import SceneError, load_scene, preset_names
from arm_sim_ros.physics.simulator import Simulator

WINDINGS = load_scene("motor_windings_hold").motors     # maxon EC 45 flat: L/R = 0.53 ms


def test_a_scene_names_no_integrator_unless_it_says_one():
    assert load_scene("release").integrator == ""
    assert load_scene("geared_arm").integrator == "exponential_rk4"
    with pytest.raises(SceneError, match="integrator 'rk5' is unknown; choose one of .*, or "
                                         "name none"):
        load_scene("release").replace(integrator="rk5")


@pytest.mark.parametrize("name", preset_names())
def test_a_preset_without_stiff_windings_takes_rk4_bit_for_bit(name):
    scene = load_scene(name)
    if scene.integrator or scene.motors and "inductance" in scene.motors:
        pytest.skip("names its method, or has windings")
    assert scene.method == "rk4"
    unnamed, rk4 = Simulator(scene), Simulator(scene.replace(integrator="rk4"))
    assert unnamed.run(0.3) == rk4.run(0.3) and unnamed.state == rk4.state


def test_stiff_windings_take_exponential_rk4_and_no_sub_steps():
    """motor_windings_hold (L/R = 0.53 ms) at h = 1 ms: rk4 would take 3 sub-steps."""
    scene = load_scene("motor_windings_hold")
    assert (scene.integrator, scene.method) == ("", "exponential_rk4")
    sim = Simulator(scene)
    assert sim.substeps == 1 and not [e for e in sim.events if e.kind == "substepping"]
    assert Simulator(scene.replace(integrator="rk4")).substeps == 3


def test_windings_that_are_not_stiff_at_the_step_keep_rk4():
    scene = load_scene("motor_windings_hold").replace(step_size=1e-4)
    assert scene.method == "rk4" and Simulator(scene).substeps == 1


def test_the_method_follows_the_step_and_the_windings():
    arm = load_scene("release").replace(motors=WINDINGS, policy="constant",
                                        constant_torque=(2.0, 1.0))
    assert arm.replace(step_size=1e-3).method == "exponential_rk4"
    assert arm.replace(step_size=1e-5).method == "rk4"
    geared = {k: WINDINGS[k] for k in ("gear_ratio", "rotor_inertia")}    # no windings
    assert arm.replace(motors=geared).method == "rk4"


def test_a_named_method_that_sub_steps_is_told_which_would_not():
    sim = Simulator(load_scene("motor_windings_hold").replace(integrator="rk4"))
    (said,) = [e.message for e in sim.events if e.kind == "substepping"]
    assert said.endswith("each 0.001 s step is taken as 3 sub-steps; exponential_rk4 would "
                         "take none (integrator: exponential_rk4)")


def test_no_method_is_named_where_none_would_take_fewer():
    """Stiff damping: every method of ours sub-steps; the message names none."""
    sim = Simulator(load_scene("damped_release").replace(damping=60.0, integrator="rk4"))
    (said,) = [e.message for e in sim.events if e.kind == "substepping"]
    assert "would take none" not in said and sim.substeps > 1


def test_a_lower_order_method_is_not_offered_for_a_higher_one():
    """Methods of at least the named one's order are offered: exponential_rk4 to euler's
    and midpoint's users; euler and midpoint never to rk4's."""
    scene = load_scene("motor_windings_hold")
    for name in ("euler", "midpoint"):
        sim = Simulator(scene.replace(integrator=name))
        said = " ".join(e.message for e in sim.events if e.kind == "substepping")
        assert "exponential_rk4" in said and sim.substeps > 1
    said = " ".join(e.message for e in Simulator(scene.replace(integrator="rk4")).events)
    assert "euler" not in said and "midpoint" not in said
