"""The ROS 2 Simulation Interfaces on the dds transport, tested on the wire with no ROS: a
client writes rmw_cyclonedds requests (as test_dds_services' clients do) and reads the
replies, the JointStates and /clock the node publishes."""
from __future__ import annotations

import logging
import sys
import threading
import time
import types

import pytest
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from arm_sim_ros.node.wire import messages as msg
from arm_sim_ros.node.services import simulate_steps as a
from arm_sim_ros.node.services import simulation as s
from arm_sim_ros.node.core import ArmSimCore
from arm_sim_ros.node.params.parameters import resolve_parameters
from arm_sim_ros.node.transports import dds_simulation as d
from arm_sim_ros.node.transports import rclpy_simulation
from arm_sim_ros.tools.wire.sim_client import SimulationClient
from node.test_dds_services import Client, start
from node.test_node_dds import CONFIG, TIMEOUT, wait_until

# The package's definitions (simulation_interfaces, jazzy branch): the fields only, which is
# what a RIHS01 hash covers.
MESSAGES = {"simulation_interfaces/msg/Result": "uint8 result\nstring error_message",
            "simulation_interfaces/msg/SimulationState": "uint8 state",
            "simulation_interfaces/msg/SimulatorFeatures":
                "uint16[] features\nstring[] spawn_formats\nstring custom_info"}
RESULT = "simulation_interfaces/msg/Result result"
SERVICES = {
    "GetSimulatorFeatures": ("", "simulation_interfaces/msg/SimulatorFeatures features"),
    "GetSimulationState": ("", "simulation_interfaces/msg/SimulationState state\n" + RESULT),
    "SetSimulationState": ("simulation_interfaces/msg/SimulationState state", RESULT),
    "StepSimulation": ("uint64 steps", RESULT),
    "ResetSimulation": ("uint8 scope", RESULT),
}


def test_type_hashes_are_rosidls():
    store = get_typestore(Stores.ROS2_JAZZY)
    for name, text in MESSAGES.items():
        store.register(get_types_from_msg(text, name))
    types = {}
    for service, (request, response) in SERVICES.items():
        for suffix, text in (("_Request", request), ("_Response", response)):
            name = f"simulation_interfaces/srv/{service}{suffix}"
            (_, definition), = get_types_from_msg(text, name).items()
            types[name] = definition
    store.register(types)
    assert {name: store.hash_rihs01(name) for name in d.TYPE_HASHES} == d.TYPE_HASHES
    # independent reference: rosidl_generator_c's step_simulation__description.c (Jazzy)
    assert d.TYPE_HASHES["simulation_interfaces/srv/StepSimulation_Request"].endswith(
        "cda33f6887815f3dce0f90e61fd8efd39bda13ae264ddede15c33fbad890630e")
    assert d.TYPE_HASHES["simulation_interfaces/srv/StepSimulation_Response"].endswith(
        "5b4acf2d0ce7c3fc125d0bef2acb9b5a81377e80db6b696b81beeffb9824fb5c")


def test_wire_type_names_are_rosidls():
    for name, request, response in d.TYPES.values():
        assert request.__idl_typename__ == f"simulation_interfaces.srv.dds_.{name}_Request_"
        assert response.__idl_typename__ == f"simulation_interfaces.srv.dds_.{name}_Response_"
        assert request().guid == 0 and response().seq == 0     # the request header first


def sim_client(participant, service, namespace=""):
    _, request, response = d.TYPES[service]
    client = Client(participant, service, node_name=namespace, types=(request, response))
    client.wait_for_service()
    return client


def readers(participant):
    deep = lambda t: msg.default_qos(t, depth=1000)  # noqa: E731 (keep every sample)
    p = participant
    return (DataReader(p, Topic(p, "rt/joint_states", msg.JointState), qos=deep(msg.JointState)),
            DataReader(p, Topic(p, "rt/clock", msg.Clock), qos=deep(msg.Clock)))


def read(reader, kind, count):
    """Exactly `count` samples (and no more within a short wait)."""
    received, deadline = [], time.monotonic() + TIMEOUT
    while len(received) < count and time.monotonic() < deadline:
        received += [m for m in reader.take(N=10000) if isinstance(m, kind)]
        time.sleep(0.001)
    time.sleep(0.02)
    received += [m for m in reader.take(N=10000) if isinstance(m, kind)]
    assert len(received) == count, (len(received), count)
    return received


def stamp(m) -> int:
    return m.sec * 10**9 + m.nanosec


def test_features_list_exactly_what_is_served():
    node, peer = start(200)
    reply = sim_client(peer, "get_simulator_features").call(node)
    assert sorted(reply.features.features) == [20, 22, 24, 25, 26, 31, 32, 33]
    assert reply.features.spawn_formats == [] and "one node tick" in reply.features.custom_info


def test_pause_step_n_ticks_with_the_clock_held_then_stop_resets_and_play_runs():
    node, peer = start(201, scene="servo_hold", publish_rate=100.0)
    get, set_state, step, reset = (sim_client(peer, name) for name in (
        "get_simulation_state", "set_simulation_state", "step_simulation", "reset_simulation"))
    joint_states, clock = readers(peer)
    wait_until(lambda: msg.matched(node.clock_writer) and msg.matched(node.joint_state_writer),
               "joint_states and /clock readers not matched")
    assert get.call(node).state.state == s.STATE_PLAYING
    for _ in range(3):
        node.tick()
    assert set_state.call(node, state=d.SimulationState(s.STATE_PAUSED)).result.result == s.RESULT_OK
    steps_before, held_stamp = node.core.sim.steps, node.core.stamp_ns()
    for _ in range(5):                       # paused: the held state at the publish rate
        node.tick()
    assert node.core.sim.steps == steps_before and node.core.stamp_ns() == held_stamp
    reply = step.call(node, steps=7)
    assert reply.result.result == s.RESULT_OK
    assert node.core.sim.steps == steps_before + 7 * node.core.config.steps_per_tick
    assert get.call(node).state.state == s.STATE_PAUSED
    # on the wire: 3 ticks, 5 held, 7 stepped; /clock held while paused, a tick per step
    tick = 10_000_000
    clocks = [stamp(m.clock) for m in read(clock, msg.Clock, 15)]
    start_ns = node.core.start_stamp_ns
    assert clocks == ([start_ns + tick * k for k in (1, 2, 3)] + [start_ns + 3 * tick] * 5
                      + [start_ns + tick * k for k in range(4, 11)])
    states = read(joint_states, msg.JointState, 15)
    assert [stamp(m.header.stamp) for m in states] == clocks
    assert len({tuple(m.position) for m in states[2:8]}) == 1      # held while paused
    # stepping while playing is refused with the standard code, and changes nothing
    assert set_state.call(node, state=d.SimulationState(s.STATE_PLAYING)).result.result == s.RESULT_OK
    refused = step.call(node, steps=1).result
    assert refused.result == s.RESULT_OPERATION_FAILED and "paused" in refused.error_message
    # stopped = reset and paused
    reply = set_state.call(node, state=d.SimulationState(s.STATE_STOPPED))
    assert reply.result.result == s.RESULT_OK and node.core.sim.steps == 0 and node.core.paused
    again = set_state.call(node, state=d.SimulationState(s.STATE_STOPPED)).result
    assert again.result == s.ALREADY_IN_TARGET_STATE
    assert reset.call(node, scope=s.SCOPE_TIME).result.result == s.RESULT_FEATURE_UNSUPPORTED
    assert reset.call(node, scope=s.SCOPE_DEFAULT).result.result == s.RESULT_OK


def ticks_since(node, before) -> int:
    return (node.core.sim.steps - before) // node.core.config.steps_per_tick


def test_a_step_call_ticks_once_per_pass_and_the_services_answer_meanwhile():
    """Issue 39: step_simulation(N) computed all N ticks before it published any and answered
    nothing meanwhile (step(1 000 000) left get_simulation_state unanswered for 15 s). Its
    ticks come one per pass of the node's loop, as SimulateSteps' do; its reply after the
    last, each tick published."""
    node, peer = start(210, scene="servo_hold", publish_rate=100.0)
    get, set_state, step = (sim_client(peer, name) for name in (
        "get_simulation_state", "set_simulation_state", "step_simulation"))
    joint_states, _ = readers(peer)
    wait_until(lambda: msg.matched(node.joint_state_writer), "joint_states reader")
    set_state.call(node, state=d.SimulationState(s.STATE_PAUSED))
    before = node.core.sim.steps
    seq = step.send(steps=300)
    wait_until(lambda: node.services.poll() is not None and ticks_since(node, before) > 0,
               "the first tick")
    answered = []
    for _ in range(10):                      # answered while the call ticks
        assert get.call(node).state.state == s.STATE_PAUSED
        answered.append(ticks_since(node, before))
    assert 0 < answered[-1] < 300 and answered == sorted(answered)
    for _ in range(5):                       # a pass: at most one tick
        ticked = ticks_since(node, before)
        node.services.poll()
        assert ticks_since(node, before) - ticked <= 1
    reply, = step.replies(node)
    assert (reply.seq, reply.result.result) == (seq, s.RESULT_OK)
    assert ticks_since(node, before) == 300
    assert len(read(joint_states, msg.JointState, 300)) == 300


def test_playing_or_stopping_interrupts_a_step_call_saying_how_far_it_came():
    node, peer = start(211, scene="servo_hold", publish_rate=100.0)
    set_state, step = (sim_client(peer, name) for name in ("set_simulation_state",
                                                           "step_simulation"))
    set_state.call(node, state=d.SimulationState(s.STATE_PAUSED))
    for target, why in ((s.STATE_STOPPED, "set stopped"), (s.STATE_PLAYING, "set playing")):
        step.send(steps=100_000)
        for _ in range(5):
            node.services.poll()
        assert set_state.call(node, state=d.SimulationState(target)).result.result == s.RESULT_OK
        reply, = step.replies(node)
        assert reply.result.result == s.RESULT_OPERATION_FAILED
        assert reply.result.error_message.startswith("interrupted after ")
        assert reply.result.error_message.endswith(f" of 100000 steps: {why}")
        if target == s.STATE_STOPPED:        # stopped is reset and paused: it stays there
            for _ in range(5):
                node.services.poll()
            assert node.core.sim.steps == 0 and node.core.paused


@pytest.mark.parametrize("scope", [s.SCOPE_TIME, s.SCOPE_TIME | s.SCOPE_STATE, s.SCOPE_ALL,
                                   s.SCOPE_SPAWNED])
def test_a_reset_scope_the_node_cannot_honour_is_refused_and_resets_nothing(scope):
    """Time only goes on (a clock that jumps back breaks use_sim_time nodes): a scope that
    holds it (SCOPE_ALL too) was answered OK with time not reset."""
    core = ArmSimCore(resolve_parameters({"scene": "servo_hold"}), logging.getLogger("t"),
                      wall_clock=lambda: 0.0, start_stamp_ns=0)
    control = s.SimulationControl(core, lambda data: None)
    core.tick(0.0)
    code, message = control.reset(scope)
    assert code == s.RESULT_FEATURE_UNSUPPORTED and "nothing was reset" in message
    assert core.sim.steps == core.config.steps_per_tick
    assert control.reset(s.SCOPE_STATE) == (s.RESULT_OK, "") and core.sim.steps == 0


@pytest.mark.parametrize("target, code", [(s.STATE_QUITTING, s.RESULT_FEATURE_UNSUPPORTED),
                                          (4, s.INCORRECT_TRANSITION),
                                          (s.STATE_PLAYING, s.ALREADY_IN_TARGET_STATE)])
def test_states_the_node_cannot_take_are_refused_with_the_packages_codes(target, code):
    node, peer = start(202)
    set_state = sim_client(peer, "set_simulation_state")
    assert set_state.call(node, state=d.SimulationState(target)).result.result == code
    assert not node.core.paused


def test_lockstep_publishes_the_clock_while_it_waits_for_the_first_command():
    """controller_manager under use_sim_time waits for /clock before it sends a command; a
    lockstep node that waited for a command first would deadlock with it."""
    node, peer = start(203, lockstep=True, lockstep_wait=0.0, real_time_factor=0.0)
    _, clock = readers(peer)
    wait_until(lambda: msg.matched(node.clock_writer), "/clock reader not matched")
    spinning = threading.Thread(target=node.spin, kwargs={"duration_s": 0.02})
    spinning.start()
    held = read_at_least(clock, msg.Clock, 3)
    assert {stamp(m.clock) for m in held} == {node.core.start_stamp_ns}   # no tick yet
    commands = DataWriter(peer, Topic(peer, "rt/joint_torque_commands", msg.Float64MultiArray),
                          qos=msg.default_qos(msg.Float64MultiArray))
    wait_until(lambda: msg.matched(commands), "command reader not matched")
    for _ in range(2):                                  # two ticks: the spin ends at 0.02 s
        commands.write(msg.Float64MultiArray(data=[0.0, 0.0]))
        time.sleep(0.05)
    spinning.join(TIMEOUT)
    assert not spinning.is_alive() and node.core.sim.time == pytest.approx(0.02)


def test_lockstep_runs_with_a_controller_that_waits_for_the_clock_to_move():
    """controller_manager (Jazzy, ros2_control_node) under use_sim_time: it waits for a
    non-zero time, sleeps one period of it, then commands once per period of /clock. With
    lockstep_wait (its default: no launch has to set it) the node ticks on its own while a
    node listens on /clock, until the commands come, then one per command."""
    node, peer = start(204, clock=time.monotonic, lockstep=True, real_time_factor=0.0)
    _, clock = readers(peer)
    commands = DataWriter(peer, Topic(peer, "rt/joint_torque_commands", msg.Float64MultiArray),
                          qos=msg.default_qos(msg.Float64MultiArray))
    wait_until(lambda: msg.matched(node.clock_writer) and msg.matched(commands), "not matched")
    spinning = threading.Thread(target=node.spin, kwargs={"duration_s": 0.5}, daemon=True)
    spinning.start()
    latest, period, sent = [0], 10_000_000, 0

    def now():
        latest.extend(stamp(m.clock) for m in clock.take(N=1000) if isinstance(m, msg.Clock))
        return max(latest)

    deadline = time.monotonic() + 2 * TIMEOUT
    while now() == 0 and time.monotonic() < deadline:       # wait_until_started
        time.sleep(0.001)
    due = now() + period                                      # sleep_for(period)
    while spinning.is_alive() and time.monotonic() < deadline:
        if now() >= due:
            commands.write(msg.Float64MultiArray(data=[0.0, 0.0]))
            sent, due = sent + 1, due + period
        time.sleep(0.001)
    spinning.join(TIMEOUT)
    assert not spinning.is_alive() and node.core.sim.time >= 0.5 - 1e-9
    assert sent >= 30                   # the commands ticked it, not the wait (0.1 s each)


def read_at_least(reader, kind, count):
    received, deadline = [], time.monotonic() + TIMEOUT
    while len(received) < count and time.monotonic() < deadline:
        received += [m for m in reader.take(N=10000) if isinstance(m, kind)]
        time.sleep(0.001)
    assert len(received) >= count
    return received


def harness_run(domain_id):
    """The docs' harness (docs/guides/servos.md) with arm_sim_ros.tools.wire.sim_client: stop, command,
    step; every JointState it read."""
    node = start(domain_id, scene="servo_hold", command_timeout=0.0)[0]
    sim = SimulationClient(domain_id=domain_id, config=CONFIG, serve=node.services.poll)
    sim.wait_for_node()
    for _ in range(3):                       # some ticks before: a reset forgets them
        node.tick()
    sim.received_joint_states()
    assert sim.stop() == s.RESULT_OK and sim.state() == s.STATE_STOPPED
    sim.command("position", [0.8, -0.2])
    assert sim.step(60) == s.RESULT_OK and sim.state() == s.STATE_PAUSED
    return sim.received_joint_states()


def test_a_harness_run_is_deterministic_run_to_run():
    first, second = harness_run(204), harness_run(205)
    assert len(first) == len(second) == 60
    assert [list(m.position) for m in first] == [list(m.position) for m in second]
    assert [list(m.velocity) for m in first] == [list(m.velocity) for m in second]
    assert first[-1].position[0] > 0.6       # moving toward the commanded 0.8 rad


class FakeNode:
    """What rclpy_simulation.serve uses of an rclpy node: create_service and the logger."""

    def __init__(self):
        self.services, self.lines, self.readers = {}, [], {"simulate_steps/_action/feedback": 1}

    def count_subscribers(self, topic):
        return self.readers.get(topic, 0)

    def create_service(self, kind, name, handler):
        self.services[name] = (kind, handler)
        return name

    def get_logger(self):
        return types.SimpleNamespace(info=self.lines.append)


def fake_simulation_interfaces(monkeypatch):
    """simulation_interfaces' Python types as rosidl makes them: keyword constructors and
    the constants the handlers read."""
    def message(name, **constants):
        def init(self, **fields):
            self.__dict__.update(fields)
        return type(name, (), {"__init__": init, **constants})
    package = types.ModuleType("simulation_interfaces")
    package.msg = types.ModuleType("simulation_interfaces.msg")
    package.srv = types.ModuleType("simulation_interfaces.srv")
    package.msg.Result = message("Result", RESULT_OK=s.RESULT_OK)
    package.msg.SimulationState = message("SimulationState")
    package.msg.SimulatorFeatures = message("SimulatorFeatures")
    for name, _, _ in d.TYPES.values():
        setattr(package.srv, name, name)
    package.action = types.ModuleType("simulation_interfaces.action")
    package.action.SimulateSteps = types.SimpleNamespace(
        Result=message("SimulateSteps.Result"), Feedback=message("SimulateSteps.Feedback"))
    # rclpy's ActionServer as far as serve uses it: it keeps what it was given
    rclpy = types.ModuleType("rclpy")
    rclpy.action = types.ModuleType("rclpy.action")
    rclpy.action.CancelResponse = types.SimpleNamespace(ACCEPT="accept")
    rclpy.action.ActionServer = lambda node, kind, name, **callbacks: types.SimpleNamespace(
        kind=kind, name=name, **callbacks)
    for module in (package, package.msg, package.srv, package.action, rclpy, rclpy.action):
        monkeypatch.setitem(sys.modules, module.__name__, module)


def served_by_fakes(monkeypatch):
    """(fake node, what it published, its SimulationControl) with the package faked."""
    fake_simulation_interfaces(monkeypatch)
    node, published = FakeNode(), []
    core = ArmSimCore(resolve_parameters({"scene": "servo_hold"}), logging.getLogger("t"),
                      wall_clock=lambda: 0.0, start_stamp_ns=0)
    return node, published, s.SimulationControl(core, published.append)


def test_on_rclpy_the_same_services_are_served_when_the_package_imports(monkeypatch):
    node, published, control = served_by_fakes(monkeypatch)
    *served, action = rclpy_simulation.serve(node, control)
    assert served == list(s.SERVICES) and action.name == "simulate_steps"
    assert action.cancel_callback(None) == "accept"
    assert {name: kind for name, (kind, _) in node.services.items()} == {
        service: name for service, (name, _, _) in d.TYPES.items()}
    call = lambda name, **fields: node.services[name][1](  # noqa: E731
        types.SimpleNamespace(**fields), types.SimpleNamespace())
    assert sorted(call("get_simulator_features").features.features) == list(s.FEATURES)
    paused = types.SimpleNamespace(state=s.STATE_PAUSED)
    assert call("set_simulation_state", state=paused).result.result == s.RESULT_OK
    step = node.services["step_simulation"][1](types.SimpleNamespace(steps=4),
                                                types.SimpleNamespace())
    turns = 0
    while True:             # the coroutine as rclpy's executor runs it: a tick per turn
        try:
            step.send(None)
        except StopIteration as end:
            reply = end.value
            break
        turns += 1
        assert len(published) == turns       # one tick per turn of the executor
    assert reply.result.result == s.RESULT_OK and len(published) == 4
    assert call("get_simulation_state").state.state == s.STATE_PAUSED
    assert call("reset_simulation", scope=s.SCOPE_DEFAULT).result.result == s.RESULT_OK


def test_on_rclpy_without_the_package_one_line_says_so(monkeypatch):
    monkeypatch.setitem(sys.modules, "simulation_interfaces", None)    # import fails
    node = FakeNode()
    assert rclpy_simulation.serve(node, None) == []
    assert len(node.lines) == 1 and "simulation_interfaces is not installed" in node.lines[0]


class FakeGoalHandle:
    """What the SimulateSteps execute callback uses of rclpy's ServerGoalHandle."""

    def __init__(self, steps):
        self.request = types.SimpleNamespace(steps=steps)
        self.is_cancel_requested, self.feedback, self.ended = False, [], None

    def publish_feedback(self, feedback):
        self.feedback.append((feedback.completed_steps, feedback.remaining_steps))

    def abort(self):
        self.ended = "aborted"

    def canceled(self):
        self.ended = "canceled"

    def succeed(self):
        self.ended = "succeeded"


def run_goal(execute, handle, cancel_after=None):
    """The coroutine as rclpy's executor runs it: resumed after each turn it gives."""
    coroutine, turns = execute(handle), 0
    while True:
        try:
            coroutine.send(None)
        except StopIteration as end:
            return end.value.result
        turns += 1
        handle.is_cancel_requested = turns == cancel_after


def test_on_rclpy_the_action_follows_the_same_rules(monkeypatch):
    node, published, control = served_by_fakes(monkeypatch)
    execute = rclpy_simulation.serve(node, control)[-1].execute_callback
    playing = FakeGoalHandle(3)
    result = run_goal(execute, playing)
    assert playing.ended == "aborted" and result.result == s.RESULT_OPERATION_FAILED
    assert "paused" in result.error_message and not published
    control.set_state(s.STATE_PAUSED)
    done = FakeGoalHandle(4)
    assert run_goal(execute, done).result == s.RESULT_OK and done.ended == "succeeded"
    assert done.feedback == [(1, 3), (2, 2), (3, 1), (4, 0)] and len(published) == 4
    stopped = FakeGoalHandle(100)
    result = run_goal(execute, stopped, cancel_after=2)
    assert stopped.ended == "canceled" and result.error_message == "canceled after 2 of 100 steps"
    assert len(published) == 6


def test_on_rclpy_a_goals_first_tick_waits_a_moment_for_a_reader_of_its_feedback(monkeypatch):
    node, published, control = served_by_fakes(monkeypatch)
    execute = rclpy_simulation.serve(node, control)[-1].execute_callback
    control.set_state(s.STATE_PAUSED)
    node.readers.clear()
    handle, turns = FakeGoalHandle(2), 0
    coroutine = execute(handle)
    for turns in range(1, 10_000_000):
        coroutine.send(None)
        if turns == 1000:       # no reader yet: no tick
            assert not published and not handle.feedback
            node.readers["simulate_steps/_action/feedback"] = 1
        if published:
            break
    assert 1000 < turns < 1010 and handle.feedback == [(1, 1)]
    with pytest.raises(StopIteration):
        while True:
            coroutine.send(None)
    nobody = FakeGoalHandle(1)
    node.readers.clear()
    started = time.monotonic()
    assert run_goal(execute, nobody).result == s.RESULT_OK and nobody.feedback == [(1, 0)]
    assert time.monotonic() - started >= a.FEEDBACK_WAIT
