"""The node runs every effect scene: per-joint damping as a parameter, the payload as a
parameter that grasps and releases at run time, and JointState effort is the torque the
joints receive (after effort limits and motor windings)."""
import logging

import pytest

from arm_sim_ros.node.core import ArmSimCore
from arm_sim_ros.node.parameters import ParameterRefused, resolve_parameters
from arm_sim_ros.physics.scene import load_scene, preset_names
from arm_sim_ros.physics.simulator import Simulator

EFFECT_PRESETS = sorted(n for n in preset_names() if Simulator(load_scene(n)).dynamics.effects
                        and set(Simulator(load_scene(n)).dynamics.effects)
                        - {"gravity", "actuator", "damping"} or n == "per_joint_damping")


def make_core(**overrides):
    return ArmSimCore(resolve_parameters(overrides), logging.getLogger("test_node_effects"),
                      wall_clock=lambda: 0.0, start_stamp_ns=0)


@pytest.mark.parametrize("scene", EFFECT_PRESETS)
def test_every_effect_scene_runs_on_the_node_as_offline(scene):
    core = make_core(scene=scene, publish_rate=10.0)
    for _ in range(5):
        state = core.tick(0.0)
    offline = Simulator(core.config.scene)
    offline.run(core.sim.time)
    assert not core.held
    assert core.sim.state == offline.state                 # the same simulation, bit for bit
    assert state.effort == list(offline.joint_torque())


def test_per_joint_damping_is_one_parameter_with_two_values():
    core = make_core(scene="per_joint_damping")
    assert core.config.values["damping"] == [0.5, 0.05]
    core.set_parameters({"damping": [0.1, 0.2]})
    assert core.sim.scene.damping == (0.1, 0.2)


def test_effort_is_what_the_joint_receives_after_the_effort_limit():
    core = make_core(scene="effort_limited_hold")
    state = core.tick(0.0)
    # gravity compensation asks for ~19.6 N m at the shoulder; the limit is 15 N m
    assert abs(state.effort[0]) == pytest.approx(15.0)


def test_payload_mass_grasps_and_releases_without_a_restart_and_the_books_close():
    core = make_core(scene="release", publish_rate=100.0)
    for _ in range(20):
        core.tick(0.0)
    time_before = core.sim.time
    assert core.set_parameters({"payload_mass": 0.5}) == ["payload_mass"]
    assert core.sim.time == time_before and core.sim.scene.payload == {"mass": 0.5}
    for _ in range(20):
        core.tick(0.0)
    core.set_parameters({"payload_mass": 0.0})
    for _ in range(20):
        core.tick(0.0)
    assert core.sim.channel_values(core.sim.state)["payload_exchange"] != 0.0
    assert abs(core.sim.residual()) < 1e-4       # RK4's error at h = 0.01 s over 0.6 s


def test_a_negative_payload_is_refused_and_changes_nothing():
    core = make_core(scene="release")
    with pytest.raises(ParameterRefused, match="payload_mass"):
        core.set_parameters({"payload_mass": -1.0})
    assert core.sim.scene.payload is None


def test_a_driver_saturating_later_in_the_run_is_logged_when_it_happens(tmp_path, caplog):
    scene = tmp_path / "weak_driver.yaml"
    scene.write_text("gravity: 0.0\npolicy: command\nstep_size: 0.001\nmotors:\n"
                     "  gear_ratio: [100.0, 50.0]\n  rotor_inertia: [1.81e-5, 1.81e-5]\n"
                     "  resistance: [0.573, 0.573]\n  inductance: [0.301e-3, 0.301e-3]\n"
                     "  torque_constant: [0.0404, 0.0404]\n  voltage_limit: [2.0, 2.0]\n")
    core = make_core(scene=str(scene), publish_rate=100.0)
    core.sim.set_command(0.0, 0.0)
    with caplog.at_level(logging.WARNING):
        for _ in range(3):
            core.tick(0.0)
        assert not [r for r in caplog.records if "saturates" in r.getMessage()]
        core.on_command([40.0, 0.0])          # 0.573 * 40 / (100 * 0.0404) = 5.7 V > 2 V
        for _ in range(3):
            core.tick(0.0)
    assert core.sim.saturated_steps > 0
    assert [r for r in caplog.records if "motor driver saturates" in r.getMessage()]


# ros2_control's topic-based hardware interface sends JointState commands: efforts by name.

def test_a_joint_state_command_drives_the_joints_by_name_in_any_order():
    core = make_core(scene="shoulder_torque_no_gravity", policy="command")
    assert core.on_joint_state_command(["elbow_joint", "shoulder_joint"], [], [], [0.5, 2.0]) is None
    assert core.command == (2.0, 0.5)
    assert core.on_joint_state_command(["elbow_joint"], [], [], [-1.0]) is None   # one joint
    assert core.command == (2.0, -1.0)


@pytest.mark.parametrize("names, position, velocity, effort, reason", [
    (["shoulder_joint"], [0.3], [], [], "the node is torque-driven"),
    (["wrist_joint"], [], [], [1.0], "unknown joint 'wrist_joint'"),
    (["shoulder_joint", "elbow_joint"], [], [], [1.0], "2 names but 1 efforts"),
    (["shoulder_joint", "shoulder_joint"], [], [], [1.0, 2.0], "named twice"),
    (["shoulder_joint"], [], [], [float("nan")], "not finite"),
])
def test_a_joint_state_command_that_is_not_a_torque_command_is_refused_and_counted(
        names, position, velocity, effort, reason):
    core = make_core(scene="release", policy="command")
    assert reason in core.on_joint_state_command(names, position, velocity, effort)
    assert core.refused_commands == 1 and core.command == (0.0, 0.0)


def test_switches_inside_steps_are_counted_in_the_diagnostics():
    core = make_core(scene="stick_slip", publish_rate=10.0)
    for _ in range(30):
        core.tick(0.0)
    values = dict(core.diagnostics(0.0).values)
    counted = dict(item.split("=") for item in values["switch_events"].split())
    assert counted == {k: str(n) for k, n in core.sim.switch_events.items()} and counted
    assert dict(make_core(scene="release").diagnostics(0.0).values)["switch_events"] == "0"
