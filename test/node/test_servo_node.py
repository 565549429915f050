"""Position and velocity commands on the node core: JointState fields by joint interface,
the set-point topics, the interface switched live, and the timeout on every interface."""
from __future__ import annotations

import logging

import pytest

from arm_sim_ros.node.core import ArmSimCore
from arm_sim_ros.node.params.parameters import resolve_parameters
from arm_sim_ros.node.params.values import ParameterRefused

NAMES = ["shoulder_joint", "elbow_joint"]


def make_core(**overrides):
    return ArmSimCore(resolve_parameters({"scene": "servo_hold"} | overrides),
                      logging.getLogger("test_servo_node"), wall_clock=lambda: 0.0,
                      start_stamp_ns=0)


def ticks(core, n):
    for _ in range(n):
        state = core.tick(0.0)
    return state


def test_the_servo_scene_starts_held_at_its_initial_pose():
    state = ticks(make_core(), 100)
    assert state.position == pytest.approx([0.3, 0.6], abs=1e-9)


def test_a_joint_state_position_command_brings_each_joint_within_a_milliradian():
    core = make_core(command_timeout=0.0)
    assert core.on_joint_state_command(NAMES[::-1], [-0.4, 0.9], [], []) is None   # by name
    state = ticks(core, 300)
    assert state.position == pytest.approx([0.9, -0.4], abs=1e-3)
    assert core.refused_commands == 0


def test_a_velocity_command_holds_the_joint_velocity_in_steady_state():
    core = make_core(**{"servo.interface": ["velocity", "position"], "servo.kd": [0.0, 15.0],
                        "servo.kp": [50.0, 100.0]}, command_timeout=0.0)
    assert core.on_setpoint_command("velocity", [0.8, float("nan")]) is None
    ticks(core, 200)
    worst = max(abs(ticks(core, 1).velocity[0] - 0.8) for _ in range(200))
    assert worst < 1e-3


def test_position_commands_topic_sets_the_position_set_points():
    core = make_core(command_timeout=0.0)
    assert core.on_setpoint_command("position", [0.1, float("nan")]) is None   # NaN: unset
    state = ticks(core, 300)
    assert state.position == pytest.approx([0.1, 0.6], abs=1e-3)


@pytest.mark.parametrize("fields, interface, ignored", [
    (([], [], [1.0, 1.0]), ["position", "position"], "effort"),
    (([0.2, 0.2], [], []), ["effort", "position"], "position"),
    (([0.2, 0.2], [], []), ["velocity", "position"], "position"),
    (([0.2, 0.2], [0.0, 0.0], [1e9, 1.0]), ["position", "position"], "effort"),   # any value
])
def test_a_field_the_joints_interface_does_not_take_is_ignored_and_said_once_at_info(
        fields, interface, ignored, caplog):
    """ros2_control's topic-based hardware sends every interface of every joint, and a
    deactivated controller leaves its last values in them: never a reason to refuse."""
    core = make_core(**{"servo.interface": interface}, command_timeout=0.0)
    with caplog.at_level(logging.INFO):
        for _ in range(5):
            assert core.on_joint_state_command(NAMES, *fields) is None
    assert core.refused_commands == 0
    said = [r for r in caplog.records if r.getMessage().startswith("shoulder_joint")
            and f"ignores the {ignored} it is sent" in r.getMessage()]
    assert len(said) == 1 and said[0].levelno == logging.INFO
    assert said[0].getMessage().startswith(f"shoulder_joint is on {interface[0]}")


def test_a_position_joint_ignores_an_effort_and_holds_its_set_point():
    core = make_core(command_timeout=0.0)
    for _ in range(100):
        assert core.on_joint_state_command(NAMES, [0.5, 0.2], [0.0, 0.0], [40.0, -40.0]) is None
        state = core.tick(0.0)
    for _ in range(200):
        state = core.tick(0.0)
    assert state.position == pytest.approx([0.5, 0.2], abs=1e-3)


@pytest.mark.parametrize("fields, interface, reason", [
    (([0.2], [], []), ["position", "position"], "2 names but 1 positions"),
    (([], [], []), ["position", "position"], "it carries no position, velocity or effort"),
    (([float("inf"), 0.2], [], []), ["position", "position"],
     "shoulder_joint position = inf rad is not finite or beyond 1e+06"),
    (([1e300, 0.2], [], []), ["position", "position"], "is not finite or beyond"),
    (([], [0.2, float("-inf")], []), ["velocity", "position"], "elbow_joint velocity = -inf"),
    (([], [], [60.0, 0.0]), ["effort", "position"],
     "|shoulder_joint effort| = 60 N m exceeds torque_limit 50 N m"),
    (([], [], [float("nan"), float("inf")]), ["effort", "effort"], "elbow_joint effort = inf"),
])
def test_a_value_a_joint_takes_is_checked_and_a_malformed_message_refused_in_one_line(
        fields, interface, reason, caplog):
    core = make_core(**{"servo.interface": interface})
    with caplog.at_level(logging.WARNING):
        for _ in range(5):
            assert reason in core.on_joint_state_command(NAMES, *fields)
    assert core.refused_commands == 5
    assert len([r for r in caplog.records if "refused" in r.getMessage()]) == 1   # rate-limited
    assert core.sim.state[0:2] == pytest.approx((0.3, 0.6))


def test_a_set_point_array_for_a_joint_on_another_interface_is_ignored():
    core = make_core(**{"servo.interface": ["effort", "position"]}, command_timeout=0.0)
    assert core.on_setpoint_command("position", [0.1, 0.2]) is None       # joint 1 ignores it
    assert core.sim.dynamics.active[-1].setpoint[0:2] == [0.3, 0.2]
    assert core.on_setpoint_command("position", [float("inf"), 0.2]) is None
    assert "expected 2" in core.on_setpoint_command("velocity", [0.1])
    assert "beyond" in core.on_setpoint_command("position", [0.1, float("inf")])
    assert core.refused_commands == 2


def test_after_a_switch_to_effort_a_command_naming_one_joint_is_taken(caplog):
    """The bumpless switch holds tau - g(q) on the joint it does not name, which can be more
    than torque_limit (-50 - 17 N m here): only the values a message carries are checked."""
    core = make_core(command_timeout=0.0)
    core.on_joint_state_command(NAMES, [-1.5, 0.6], [], [])   # the shoulder's servo saturates
    ticks(core, 15)
    core.set_parameters({"servo.interface": ["effort", "effort"]})
    held = core.command[0]
    assert abs(held) > core.config.values["torque_limit"]
    with caplog.at_level(logging.WARNING):
        for _ in range(20):
            assert core.on_joint_state_command([NAMES[1]], [], [], [1.0]) is None
            ticks(core, 1)
    assert core.refused_commands == 0
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert core.command == (held, 1.0)


def test_a_velocity_joint_takes_its_own_gains_and_a_switch_back_finds_the_position_ones():
    """servo_hold's velocity_kp and velocity_ki; kd, a position joint's, is not used there."""
    core = make_core(command_timeout=0.0)
    servo = core.sim.dynamics.active[-1]
    position_gains = (servo.kp, servo.ki, servo.kd)
    core.set_parameters({"servo.interface": ["velocity", "velocity"]})
    servo = core.sim.dynamics.active[-1]
    assert (servo.kp, servo.ki, servo.kd) == ((52.0, 17.0), (400.0, 200.0), (0.0, 0.0))
    assert core.on_setpoint_command("velocity", [0.3, -0.2]) is None
    ticks(core, 100)
    worst = max(max(abs(v - t) for v, t in zip(ticks(core, 1).velocity, (0.3, -0.2)))
                for _ in range(50))
    assert worst < 2e-3
    core.set_parameters({"servo.interface": ["position", "position"]})
    servo = core.sim.dynamics.active[-1]
    assert (servo.kp, servo.ki, servo.kd) == position_gains
    q = core.sim.state[0:2]
    assert ticks(core, 200).position == pytest.approx(q, abs=0.02)
    assert ticks(core, 1).velocity == pytest.approx([0.0, 0.0], abs=1e-3)


def test_switching_a_joints_interface_live_is_bumpless():
    core = make_core(command_timeout=0.0)
    core.on_joint_state_command(NAMES, [0.5, 0.2], [], [])
    ticks(core, 20)                                    # moving toward it
    before = core.sim.joint_torque()
    assert core.set_parameters({"servo.interface": ["effort", "position"]}) == ["servo.interface"]
    assert core.sim.joint_torque() == pytest.approx(before, abs=1e-9)
    assert core.config.values["servo.interface"] == ["effort", "position"]
    # back to position: set-point is where the joint is now, the torque continuous
    q = core.sim.state[0]
    before = core.sim.joint_torque()
    core.set_parameters({"servo.interface": ["position", "position"]})
    assert core.sim.joint_torque() == pytest.approx(before, abs=1e-9)
    assert ticks(core, 1).position[0] == pytest.approx(q, abs=0.02)


def test_an_unknown_interface_is_refused_and_nothing_changes():
    core = make_core()
    with pytest.raises(ParameterRefused, match="servo.interface"):
        core.set_parameters({"servo.interface": ["torque", "position"]})
    assert core.config.values["servo.interface"] == ["position", "position"]


def test_no_command_is_held_forever_a_timed_out_set_point_holds_where_the_arm_is(caplog):
    core = make_core(command_timeout=0.1)
    core.on_setpoint_command("velocity", [0.5, float("nan")])   # position joints take it
    with caplog.at_level(logging.WARNING):
        ticks(core, 10)                                # 0.1 s: times out
        q = core.sim.state[0]
        state = ticks(core, 200)
    assert core.command_timeouts == 1
    assert [r for r in caplog.records if "servos hold where they are" in r.getMessage()]
    assert abs(state.velocity[0]) < 1e-3 and abs(state.position[0] - q) < 0.05


def test_a_servo_rate_set_live_samples_the_commands_and_a_bad_one_is_refused():
    core = make_core(command_timeout=0.0)
    core.on_joint_state_command(NAMES, [0.8, -0.2], [], [])
    ticks(core, 10)
    before = core.sim.joint_torque()
    assert core.set_parameters({"servo.rate": 1000.0}) == ["servo.rate"]   # every step
    assert core.sim.joint_torque() == pytest.approx(before, abs=1e-9)   # bumpless
    assert core.sim.sampled is not None
    state = ticks(core, 300)
    assert state.position == pytest.approx([0.8, -0.2], abs=1e-3)
    with pytest.raises(ParameterRefused, match="servo.rate = 1e.06 Hz samples 1000 times"):
        core.set_parameters({"servo.rate": 1e6})
    assert core.config.values["servo.rate"] == 1000.0


ENTRIES = {   # every way a set-point reaches the servos: (core, joint 1's value) -> refusal
    "joint_commands position": lambda core, v: core.on_joint_state_command(
        NAMES, [v, 0.6], [], []),
    "joint_commands velocity": lambda core, v: core.on_joint_state_command(
        NAMES, [], [v, 0.0], []),
    "position_commands": lambda core, v: core.on_setpoint_command("position", [v, 0.6]),
    "velocity_commands": lambda core, v: core.on_setpoint_command("velocity", [v, 0.0]),
}


@pytest.mark.parametrize("value", [float("inf"), -float("inf"), 1e300, 1.0000001e6])
@pytest.mark.parametrize("entry", list(ENTRIES))
def test_every_way_into_the_set_points_is_range_checked_alike(entry, value):
    """Issue 39: a JointState with position [inf, 0.6] on joint_commands was taken and the
    next tick went NaN (the held arm until reset); position_commands refused it. The check
    is where each value a joint takes is checked (intake.value_refusal), one bound (1e6)."""
    core = make_core(command_timeout=0.0)
    reason = ENTRIES[entry](core, value)
    assert reason is not None and "is not finite or beyond 1e+06" in reason, reason
    assert core.refused_commands == 1
    state = ticks(core, 50)
    assert state.position == pytest.approx([0.3, 0.6], abs=1e-9)       # held as it was
    assert core.sim.fault is None


def test_a_scene_set_point_is_bounded_as_the_commands_are():
    from arm_sim_ros.physics.scene import SceneError, load_scene
    with pytest.raises(SceneError, match="beyond 1e"):
        load_scene("servo_reach").replace(setpoint=(1e300, 0.0))
