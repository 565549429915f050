"""The node runs every effect scene, and every effect is a parameter named as the scene file
names its key (`friction.coulomb`, `effort_limits`, `payload.mass`...): set at start it is the
scene file's value; the safe ones (payload, effort limits, friction, damping, the controller's
model) change while it runs, from the next step, with the state and the energy books carried
over; the others are refused live as start-only. JointState effort is the torque the joints
receive (after effort limits and motor windings)."""
import logging
import math

import pytest

from arm_sim_ros.node.core import ArmSimCore
from arm_sim_ros.node.main import main as node_main
from arm_sim_ros.node.params.parameters import (EFFECT_PARAMETERS, LIVE, START_ONLY,
                                                ParameterRefused, resolve_parameters)
from arm_sim_ros.node.params.ros_args import load_params_file
from arm_sim_ros.physics import model
from arm_sim_ros.physics.scene import MAPPINGS
from arm_sim_ros.physics.scene import load_scene, preset_names
from arm_sim_ros.physics.simulator import Simulator

# Every preset with an effect beyond gravity, the actuator and damping, and per-joint damping.
EFFECT_PRESETS = sorted(n for n in preset_names() if n == "per_joint_damping" or set(
    Simulator(load_scene(n)).dynamics.effects) - {"gravity", "actuator", "damping"})


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


def test_payload_grasps_and_releases_live_without_a_restart_and_the_books_close():
    core = make_core(scene="release", publish_rate=100.0)
    for _ in range(20):
        core.tick(0.0)
    time_before = core.sim.time
    assert core.set_parameters({"payload.mass": 0.5}) == ["payload.mass"]
    assert core.sim.time == time_before and core.sim.scene.payload == {"mass": 0.5}
    for _ in range(20):
        core.tick(0.0)
    core.set_parameters({"payload.mass": 0.0})
    for _ in range(20):
        core.tick(0.0)
    assert core.sim.channel_values(core.sim.state)["payload_exchange"] != 0.0
    assert abs(core.sim.residual()) < 1e-4       # RK4's error at h = 0.01 s over 0.6 s


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


def test_a_nan_effort_is_ros2_controls_unset_command_not_a_bad_one():
    """Until a controller writes them, the hardware interface sends its command interfaces'
    NaN: not commanded (seen against a real controller_manager: 9519 refusals in 23 s)."""
    nan = float("nan")
    core = make_core(scene="shoulder_torque_no_gravity", policy="command")
    assert core.on_joint_state_command(["shoulder_joint", "elbow_joint"], [], [], [nan, nan]) is None
    assert core.command == (0.0, 0.0) and core.commands.refused == 0
    assert core.on_joint_state_command(["shoulder_joint", "elbow_joint"], [], [], [nan, 3.0]) is None
    assert core.command == (0.0, 3.0) and core.commands.refused == 0


@pytest.mark.parametrize("names, effort, reason", [
    (["wrist_joint"], [float("nan")], "unknown joint 'wrist_joint'"),
    (["wrist_joint", "elbow_joint"], [float("nan"), 1.0], "unknown joint 'wrist_joint'"),
    (["shoulder_joint", "shoulder_joint"], [float("nan"), 1.0], "named twice"),
    (["shoulder_joint", "elbow_joint"], [float("nan"), float("inf")], "not finite"),
])
def test_a_nan_effort_does_not_hide_what_else_is_wrong_with_the_command(names, effort, reason):
    core = make_core(scene="release", policy="command")
    assert reason in core.on_joint_state_command(names, [], [], effort)
    assert core.refused_commands == 1 and core.command == (0.0, 0.0)


def test_a_position_or_velocity_for_a_torque_driven_joint_is_ignored():
    """What ros2_control's topic-based hardware sends for every interface of every joint:
    an effort joint takes the effort and ignores the rest, refusing none of it."""
    core = make_core(scene="release", policy="command")
    assert core.on_joint_state_command(["shoulder_joint"], [0.3], [1e9], []) is None
    assert core.refused_commands == 0 and core.command == (0.0, 0.0)
    assert core.on_joint_state_command(["shoulder_joint"], [0.3], [0.0], [2.0]) is None
    assert core.command == (2.0, 0.0)


@pytest.mark.parametrize("names, position, velocity, effort, reason", [
    (["shoulder_joint"], [], [], [], "it carries no position, velocity or effort"),
    (["wrist_joint"], [], [], [1.0], "unknown joint 'wrist_joint'"),
    (["shoulder_joint", "elbow_joint"], [], [], [1.0], "2 names but 1 efforts"),
    (["shoulder_joint", "shoulder_joint"], [], [], [1.0, 2.0], "named twice"),
    (["shoulder_joint"], [], [], [float("inf")], "not finite"),   # NaN: unset (above)
])
def test_a_malformed_joint_state_command_is_refused_and_counted(
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


# --- every effect is a parameter, named as the scene file names its key --------------------

# A value for every key of every effect (hard joint limits; the compliant ones below): the
# scene file EVERY_EFFECT_SCENE names the same keys with the same values.
AT_START = {
    "effort_limits": [15.0, 10.0],
    "springs.stiffness": [20.0, 5.0], "springs.rest_positions": [0.5, -0.5],
    "payload.mass": 0.5,
    "motors.gear_ratio": [100.0, 50.0], "motors.rotor_inertia": [1.81e-5, 1.81e-5],
    "motors.resistance": [0.573, 0.573], "motors.inductance": [0.301e-3, 0.301e-3],
    "motors.torque_constant": [0.0404, 0.0404], "motors.voltage_limit": [48.0, 48.0],
    "controller_model.gravity": 9.0, "controller_model.link_masses": [1.1, 0.9],
    "controller_model.com_distances": [0.5, 0.45], "controller_model.link_lengths": [1.0, 0.95],
    "controller_model.payload_mass": 0.4,
    "friction.coulomb": [0.3, 0.1], "friction.static": [0.4, 0.15],
    "friction.stribeck_velocity": 0.05,
    "joint_limits.lower": [-2.0, -2.5], "joint_limits.upper": [2.0, 2.5],
    "joint_limits.restitution": 0.5,
}
COMPLIANT = {"joint_limits.lower": [-0.5, -2.5], "joint_limits.upper": [0.5, 2.5],
             "joint_limits.stiffness": 500.0, "joint_limits.damping": 2.0}
SERVO = {"servo.interface": ["position", "velocity"], "servo.kp": [200.0, 20.0],
         "servo.ki": [100.0, 10.0], "servo.kd": [30.0, 8.0], "servo.integral_limit": [20.0, 5.0],
         "servo.velocity_kp": [25.0, 15.0], "servo.velocity_ki": [90.0, 12.0],
         "servo.tracking": [2.0, 1.0], "servo.rate": 1000.0}
SENSED = {"sensors.seed": 7.0, "sensors.rate": 500.0, "sensors.position_resolution": [1e-3, 1e-3],
          "sensors.position_noise": [1e-4, 1e-4], "sensors.position_offset": [0.01, 0.0],
          "sensors.velocity": "differences", "sensors.velocity_noise": None,
          "sensors.delay": 0.002}     # test/node/test_sensors_node.py runs them
POLICY = {"hard_limits": "gravity_compensation", "compliant_limits": "gravity_compensation",
          "servo": "command_gravity_compensation"}


def scene_text(values: dict) -> str:
    """The same keys as a scene file writes them: `effect: {key: value}` mappings."""
    lines, effects = [], {}
    for name, value in values.items():
        effect, dot, key = name.partition(".")
        if dot:
            effects.setdefault(effect, []).append(f"  {key}: {value}")
        else:
            lines.append(f"{name}: {value}")
    for effect, keys in effects.items():
        lines += [f"{effect}:", *keys]
    return "\n".join(lines) + "\n"


def test_every_key_of_every_effect_is_one_parameter_named_as_the_scene_file_names_it():
    keys = {"effort_limits"} | {f"{effect}.{p.name}" for effect, kind in MAPPINGS.items()
                                for p in kind.parameters}
    assert ({spec.name for spec in EFFECT_PARAMETERS} == keys
            == set(AT_START) | set(COMPLIANT) | set(SERVO) | set(SENSED))
    # double, double[], string[] (the servo's interface names), string (sensors.velocity),
    # integer (sensors.seed)
    assert {spec.kind for spec in EFFECT_PARAMETERS} == {"float", "float_pair", "str_list",
                                                         "str", "int"}


@pytest.mark.parametrize("values", [AT_START, COMPLIANT, SERVO],
                         ids=["hard_limits", "compliant_limits", "servo"])
def test_every_effect_set_at_start_reaches_the_simulator_as_the_scene_file_would(tmp_path, values,
                                                                                   request):
    policy = POLICY[request.node.callspec.id]
    core = make_core(policy=policy, step_size=0.001, **values)
    path = tmp_path / "every_effect.yaml"
    path.write_text(f"policy: {policy}\nstep_size: 0.001\n" + scene_text(values))
    from_file = load_scene(str(path))
    for effect in {name.partition(".")[0] for name in values}:
        assert getattr(core.sim.scene, effect) == getattr(from_file, effect), effect
        assert getattr(core.sim.scene, effect) is not None
    for name, value in values.items():
        effect, _, key = name.partition(".")
        named = getattr(core.sim.scene, effect)
        assert (named[key] if key else named) == (tuple(value) if isinstance(value, list) else value)
    assert set(core.sim.dynamics.effects) >= {n.partition(".")[0] for n in values}   # all run


def test_a_parameter_overrides_the_scene_files_value_key_by_key():
    core = make_core(scene="stick_slip", **{"friction.coulomb": [1.0, 0.2]})
    assert core.sim.scene.friction == {"coulomb": (1.0, 0.2), "static": (4.0, 0.8),
                                       "stribeck_velocity": 0.05}


def test_an_effect_neither_the_scene_nor_a_parameter_names_is_absent_and_not_set():
    core = make_core(scene="release")
    assert set(core.sim.dynamics.effects) == {"gravity", "actuator"}
    assert all(core.config.values[spec.name] is None for spec in EFFECT_PARAMETERS)


def test_a_params_file_sets_effects_as_nested_mappings(tmp_path):
    path = tmp_path / "params.yaml"
    path.write_text("arm_sim:\n  ros__parameters:\n    effort_limits: [15.0, 10.0]\n"
                    "    friction:\n      coulomb: [0.5, 0.1]\n      stribeck_velocity: 0.0\n")
    core = make_core(**load_params_file(str(path)))
    assert core.sim.scene.effort_limits == (15.0, 10.0)
    assert core.sim.scene.friction == {"coulomb": (0.5, 0.1), "stribeck_velocity": 0.0}


def test_a_ros2_param_dump_with_keys_not_set_starts_the_node_again(tmp_path):
    """`ros2 param dump` writes a parameter that is not set as null (rcl reads "null")."""
    path = tmp_path / "dump.yaml"
    path.write_text("/arm_sim:\n  ros__parameters:\n    effort_limits: null\n"
                    "    friction:\n      coulomb: [0.5, 0.1]\n      static: null\n"
                    "    springs:\n      stiffness: null\n")
    core = make_core(**load_params_file(str(path)))
    named = make_core(**{"friction.coulomb": [0.5, 0.1]})
    assert core.sim.scene.friction == named.sim.scene.friction
    assert core.sim.scene.effort_limits is None and core.sim.scene.springs is None


def test_effects_that_change_live_are_the_safe_ones_and_every_other_effect_key_is_start_only():
    names = {spec.name for spec in EFFECT_PARAMETERS}
    live = {"effort_limits", "friction", "controller_model", "payload", "servo", "sensors"}
    assert {n.partition(".")[0] for n in names & set(LIVE)} == live
    assert set(LIVE) == {"damping", "command_delay"} | {n for n in names
                                                        if n.partition(".")[0] in live}
    assert set(START_ONLY) == {"scene", "robot_description", "joint_states_topic", "clock_origin",
                               "joint_commands_topic", "paused"} | (names - set(LIVE))


def test_arm_sim_node_help_lists_every_effect_parameter_and_whether_it_changes_live(capsys):
    with pytest.raises(SystemExit):
        node_main(["--help"])
    lines = {line.split()[0]: line for line in capsys.readouterr().out.splitlines()
             if line.startswith("  ") and line.split()}
    for spec in EFFECT_PARAMETERS:
        assert lines[spec.name].endswith("start only" if spec.name in START_ONLY
                                         else "live, state kept"), spec.name


# --- live: from the next step, the state and the books carried over ------------------------

def tick(core, n):
    for _ in range(n):
        state = core.tick(0.0)
    return state


def test_an_effort_limit_set_live_clamps_the_applied_torque_from_the_next_tick():
    core = make_core(scene="gravity_compensation_at_rest")
    held = tick(core, 10)
    assert held.effort[0] == pytest.approx(19.62, rel=1e-3)   # g1 at the horizontal pose
    before = (core.sim.state, core.sim.steps)
    assert core.set_parameters({"effort_limits": [15.0, 10.0]}) == ["effort_limits"]
    assert (core.sim.state, core.sim.steps) == before        # not a restart
    state = tick(core, 1)
    assert state.effort[0] == 15.0 and abs(state.effort[1]) < 10.0   # the shoulder saturates
    assert tick(core, 20).position[0] < -0.01                 # and the arm sags
    assert abs(core.sim.residual()) < 1e-6


def test_friction_set_live_stops_an_arm_that_would_drift_and_books_its_kinetic_energy():
    drifting = dict(scene="release", gravity=0.0, initial_velocities=[1.0, -1.0])
    free, core = make_core(**drifting), make_core(**drifting)
    tick(free, 10), tick(core, 10)
    kinetic = core.sim.sample().kinetic
    core.set_parameters({"friction.coulomb": [2.0, 1.0]})
    tick(free, 150), tick(core, 150)
    stopped = core.sim.state
    tick(free, 20), tick(core, 20)
    assert core.sim.state[:4] == stopped[:4] and stopped[2:4] == (0.0, 0.0)   # stuck, exactly
    assert abs(free.sim.state[0] - stopped[0]) > 0.5          # without friction it drifts on
    assert core.sim.channel_values(core.sim.state)["friction_loss"] == pytest.approx(
        kinetic, rel=1e-6)                                    # all of it went to friction
    assert core.sim.switch_events["stick"] == 2              # each joint stuck once


def test_a_controller_model_set_live_changes_the_compensation_as_the_believed_arm_says():
    core = make_core(scene="gravity_compensation_at_rest")
    tick(core, 10)
    core.set_parameters({"controller_model.payload_mass": 0.5})
    state = tick(core, 1)
    believed = model.gravity_torque(core.sim.scene.links.with_payload(0.5), state.position, 9.81)
    assert state.effort == pytest.approx(list(believed), rel=1e-12)
    # compensating for a payload it does not hold, the controller flexes the elbow up (and
    # the shoulder, coupled through M(q), dips)
    lifted = tick(core, 20)
    assert lifted.position[1] > 0.05 and lifted.position[0] < 0.0
    assert abs(core.sim.residual()) < 1e-6


def test_damping_changes_live_and_the_books_close_when_its_channel_goes():
    core = make_core(scene="damped_release")
    tick(core, 30)
    steps = core.sim.steps
    core.set_parameters({"damping": 0.0})
    assert core.sim.steps == steps and "dissipated" not in core.sim.channels
    assert core.sim.retired[1] > 0.1               # the loss so far, kept in the books
    tick(core, 30)
    assert abs(core.sim.residual()) < 1e-5


@pytest.mark.parametrize("scene, change, reason", [
    ("stick_slip", {"friction.static": [0.1, 0.1]}, "breakaway needs Fs >= Fc"),
    ("release", {"friction.static": [1.0, 1.0]}, "friction needs friction.coulomb"),
    ("release", {"effort_limits": [-1.0, 5.0]}, "must be positive"),
    ("release", {"effort_limits": 3.0}, "must be a list of two numbers"),
    ("release", {"friction.stribeck_velocity": math.nan}, "impossible"),
    ("release", {"controller_model.link_masses": [1.0, 0.0]}, "must be positive"),
    ("release", {"payload.mass": -0.5}, "must be non-negative"),
    ("release", {"damping": [0.1, -0.1]}, "would add energy"),
])
def test_an_invalid_live_value_is_refused_with_its_reason_and_nothing_changes(scene, change,
                                                                              reason):
    core = make_core(scene=scene)
    tick(core, 3)
    sim = core.sim
    before = (core.config, sim.scene, sim.state, sim.steps, sim.dynamics)
    with pytest.raises(ParameterRefused) as refused:
        core.set_parameters(change)
    assert refused.value.name == next(iter(change)) and reason in refused.value.reason
    assert core.sim is sim and (core.config, sim.scene, sim.state, sim.steps, sim.dynamics) == before


@pytest.mark.parametrize("name, value", [
    ("motors.resistance", [1.0, 1.0]), ("motors.gear_ratio", [10.0, 10.0]),
    ("springs.stiffness", [5.0, 5.0]), ("joint_limits.lower", [-1.0, -1.0]),
    ("joint_limits.restitution", 0.9)])
def test_an_effect_key_that_cannot_change_live_is_refused_as_start_only(name, value):
    core = make_core(step_size=0.001, **AT_START)
    tick(core, 2)
    before = (core.config, core.sim, core.sim.state)
    with pytest.raises(ParameterRefused, match="start-only") as refused:
        core.set_parameters({name: value})
    assert refused.value.name == name and f"-p {name}:=" in refused.value.reason
    assert (core.config, core.sim, core.sim.state) == before
    assert core.set_parameters({name: AT_START[name]}) == []     # its own value: no change
    assert core.set_parameters({"motors.gear_ratio": [100, 50]}) == []   # as integers, too
