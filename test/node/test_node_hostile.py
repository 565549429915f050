"""Hostile input to the node: bad commands (NaN, +-inf, wrong lengths, empty, 1e308, floods) and
fuzzed parameters. Zero crashes, zero non-finite outputs, every bad command counted, every bad
parameter refused with nothing changed. DDS tests: loopback only, domains 60-79."""
import logging
import math
import os
import random
import subprocess
import sys
import time

import pytest
from hypothesis import HealthCheck, example, given, settings, strategies as st

from arm_sim_ros import interface
from arm_sim_ros.node import core as node_core
from arm_sim_ros.node.params import parameters as node_params
from arm_sim_ros.node.wire import messages as msg
from node.node_oracle import expected_states
from node.test_node_dds import CONFIG, TIMEOUT, FakeClock, start

HOSTILE_COMMANDS = [
    [math.nan, 0.0], [0.0, math.nan], [math.nan, math.nan], [math.inf, 0.0], [-math.inf, 0.0],
    [0.0, -math.inf], [1.0], [1.0, 2.0, 3.0], [], [1e308, 0.0], [-1e308, 1e308],
    [51.0, 0.0], [0.0, -1e3], [5e-324, math.nan],
]
GOOD_COMMANDS = [(1.0, -0.5), (0.0, 2.0), (-3.0, 0.25)]
BURST = 10                     # the ROS default keep-last depth: a burst of this many arrives whole


def send_burst(node, peer, commands):
    for command in commands:
        peer.commands.write(msg.Float64MultiArray(data=list(command)))
    taken, deadline = 0, time.monotonic() + TIMEOUT
    while taken < len(commands) and time.monotonic() < deadline:
        taken += node.take_commands(timeout=0.01)
    assert taken == len(commands)


def all_finite(data):
    return all(math.isfinite(v) for v in data.position + data.velocity + data.effort)


def test_hostile_command_floods_over_dds_are_all_counted_and_never_reach_the_physics():
    node, peer = start(60, gravity=0.0, damping=0.5)
    rng = random.Random(6)
    schedule, bad = [], 0
    for tick in range(60):
        burst = [rng.choice(HOSTILE_COMMANDS) for _ in range(BURST - 1)]
        good = GOOD_COMMANDS[tick // 20] if tick % 20 == 0 else None
        burst += [good] if good else []
        send_burst(node, peer, burst)
        bad += BURST - 1
        schedule.append(good)
        node.tick()
    received = peer.read(peer.joint_states, len(schedule), msg.JointState)
    assert node.core.refused_commands == bad
    assert all(all_finite(m) for m in received)
    # the physics saw exactly the good commands, held between them
    expected = expected_states(node.core.config.scene, schedule, node.core.config.steps_per_tick)
    assert [(list(m.position), list(m.velocity), list(m.effort)) for m in received] == \
        [tuple(e) for e in expected]
    status = node.publish_diagnostics()
    values = dict(status.values)
    assert status.level == interface.WARN and values["refused_commands"] == str(bad)


def test_a_command_flood_on_the_core_is_counted_and_logged_at_a_limited_rate(caplog):
    clock = FakeClock()
    core = node_core.ArmSimCore(node_params.resolve_parameters({}), logging.getLogger("flood"), clock)
    core.on_command([0.5, 0.5])
    with caplog.at_level(logging.WARNING):
        for i in range(20_000):
            core.on_command(HOSTILE_COMMANDS[i % len(HOSTILE_COMMANDS)])
            if i % 1000 == 999:
                clock.now += 0.1            # 2 s of node time in all
        state = core.tick(clock.now)
    assert core.refused_commands == 20_000 and core.command == (0.5, 0.5)
    assert all_finite(state)
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert 1 <= len(warnings) <= 3          # one per WARN_PERIOD of node time, not 20 000


def test_a_state_that_cannot_stay_finite_is_held_and_reported_over_dds():
    """Its first step leaves the doubles: the node holds the last finite state, says so,
    and its time runs on (stamps and /clock never stand still while it runs)."""
    node, peer = start(61, initial_velocities=[5e153, -5e153])
    for _ in range(3):
        node.tick()
    received = peer.read(peer.joint_states, 3, msg.JointState)
    assert all(all_finite(m) for m in received)
    assert [list(m.velocity) for m in received] == [[5e153, -5e153]] * 3
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in received]
    assert [b - a for a, b in zip(stamps, stamps[1:])] == [10_000_000] * 2
    assert node.core.held and "holding the last finite state" in node.core.sim.fault
    assert node.publish_diagnostics().level == interface.ERROR


def test_a_held_node_still_ends_at_its_duration():
    """`arm_sim_node --duration` counts simulated time: a node held since its first step
    (time standing still, before) ran for ever; it ends, exit 0, saying it held."""
    env = dict(os.environ, ROS_DOMAIN_ID="62", ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               CYCLONEDDS_URI=CONFIG, ARM_SIM_COMPILED="0")
    done = subprocess.run(
        [sys.executable, "-m", "arm_sim_ros.node.main", "--transport", "dds", "--duration", "0.5",
         "--quiet", "--ros-args", "-p", "initial_velocities:=[5.0e153, -5.0e153]",
         "-p", "real_time_factor:=0.0"], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "holding the last finite state" in done.stderr


def test_a_torque_or_reading_that_leaves_the_doubles_at_a_finite_state_holds_the_last_message():
    """Past what a scene's start is checked for (guard.check_start), a drive could still ask
    a torque beyond the doubles at a finite state: the node publishes the last finite
    message at each new stamp, says so once, and reports itself held."""
    core = node_core.ArmSimCore(node_params.resolve_parameters({"damping": 0.5}),
                                logging.getLogger("beyond"), FakeClock())
    last = core.tick()
    core.sim.joint_torque = lambda state=None: (math.inf, math.nan)   # from now on
    held = [core.tick() for _ in range(3)]
    assert all(all_finite(data) for data in held) and core.held
    assert [d.position for d in held] == [last.position] * 3 and [d.effort for d in held] == \
        [last.effort] * 3
    stamps = [last.stamp_ns] + [d.stamp_ns for d in held]
    assert [b - a for a, b in zip(stamps, stamps[1:])] == [10_000_000] * 3
    assert core.diagnostics().level == interface.ERROR


# --- parameter fuzzing -------------------------------------------------------------------------

FUZZED = [s.name for s in node_params.PARAMETERS if not s.name.startswith("rerun_")]
hostile_numbers = st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -0.0, -1.0, 1e308, -1e308,
                                   5e-324, 1e-300, 7.0, 1e4, 0.001, 0.05, 100.0, 1.5e6])
hostile_values = st.one_of(
    hostile_numbers, st.integers(-10**30, 10**30), st.booleans(), st.none(),
    st.sampled_from(["", "rk4", "nonsense", "release", "command", "constant", "damped_release"]),
    st.lists(hostile_numbers, max_size=3), st.lists(st.text(max_size=3), max_size=3),
    st.dictionaries(st.text(max_size=2), hostile_numbers, max_size=1))


# Values of the parameter's own kind reach the physics (and are often accepted); any value
# tests the type checks.
plausible = st.one_of(hostile_numbers, st.floats(1e-3, 1e3), st.floats(-10.0, 10.0))
OF_KIND = {"float": plausible, "float_pair": st.lists(plausible, min_size=2, max_size=2),
           "float_or_pair": st.one_of(plausible, st.lists(plausible, min_size=2, max_size=2)),
           "bool": st.booleans(), "str_list": st.lists(st.text(max_size=3), max_size=3),
           "str": st.sampled_from(["", "rk4", "euler", "nonsense", "command", "constant",
                                   "gravity_compensation", "base_link"])}
parameter_changes = st.lists(
    st.sampled_from(FUZZED).flatmap(lambda name: st.tuples(st.just(name), st.one_of(
        OF_KIND[node_params.SPECS[name].kind], hostile_values))),
    min_size=1, max_size=2).map(dict)


@pytest.mark.hunt
@settings(max_examples=200, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(changes=parameter_changes)
@example(changes={"real_time_factor": 0.0, "publish_rate": 5e-324})  # rate x step underflowed
def test_fuzzed_parameters_are_refused_with_nothing_changed_or_run_finite(changes):
    core = node_core.ArmSimCore(node_params.resolve_parameters({"damping": 0.5}),
                                logging.getLogger("fuzz"), FakeClock())
    for _ in range(3):
        core.tick()
    before = (core.config, core.sim.state, core.sim.steps, core.sim)
    try:
        core.set_parameters(changes)
    except node_params.ParameterRefused as refused:
        assert refused.name in node_params.SPECS and refused.reason
        assert (core.config, core.sim.state, core.sim.steps, core.sim) == before
        assert all_finite(core.tick())
        return
    # accepted: the node runs on and publishes finite numbers, held if it must
    if core.config.steps_per_tick * core.sim.substeps > 200_000:
        return   # valid but a tick would take seconds of CPU: the node's budget, not a crash
    for _ in range(2):
        assert all_finite(core.tick())
    diagnostics = core.diagnostics()
    assert diagnostics.level in (interface.OK, interface.WARN, interface.ERROR)
    assert (diagnostics.level == interface.ERROR) == core.held


def test_diagnostics_report_substeps_for_stiff_damping():
    # d h Lambda = 200 x 0.01 x 15.09 is past RK4's limit 2.785: the guard sub-steps and says so.
    core = node_core.ArmSimCore(node_params.resolve_parameters({"damping": 200.0, "step_size": 0.01}),
                                logging.getLogger("stiff"), FakeClock())
    for _ in range(3):
        assert all_finite(core.tick())
    values = dict(core.diagnostics().values)
    assert int(values["substeps_per_step"]) == core.sim.substeps > 1
    assert int(values["substeps_taken"]) == 3 * core.sim.substeps
    assert values["refused_steps"] == "0"
