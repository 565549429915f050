"""The arm in a ROS 2 graph on the dds transport: JointState effort commands on
joint_commands (ros2_control's topic-based hardware interface), /clock with the stamps of
joint_states, lockstep (one tick per command), topics chosen by parameters. Loopback,
domains 140-149."""
import logging
import time

import pytest
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from rosbags.typesys import Stores, get_typestore

from arm_sim_ros.interface import OK
from arm_sim_ros.node.wire import messages as msg
from arm_sim_ros.node.core import ArmSimCore
from arm_sim_ros.node.params.parameters import resolve_parameters
from arm_sim_ros.node.params.values import ParameterRefused
from arm_sim_ros.node.schedule import TickSchedule
from arm_sim_ros.node.transports.dds import DdsArmSimNode
from node.test_node_dds import CONFIG, TIMEOUT, FakeClock, Peer, start, wait_until


def reader(peer, topic, message_type, qos=None):
    p = peer.participant
    return DataReader(p, Topic(p, topic, message_type),
                      qos=qos or msg.default_qos(message_type, depth=1000))


def joint_command_writer(peer, topic="rt/joint_commands"):
    p = peer.participant
    writer = DataWriter(p, Topic(p, topic, msg.JointState), qos=msg.default_qos(msg.JointState))
    wait_until(lambda: msg.matched(writer), "joint_commands not matched")
    return writer


def effort_command(names, effort):
    return msg.JointState(name=list(names), effort=list(effort))


def stamp(m):
    return m.header.stamp.sec * 10**9 + m.header.stamp.nanosec


def test_the_clock_type_hash_is_rosidls():
    assert get_typestore(Stores.ROS2_JAZZY).hash_rihs01("rosgraph_msgs/msg/Clock") == \
        msg.TYPE_HASHES[msg.ROS_TYPE_NAMES[msg.Clock]]


def clock_reader(node, peer):
    """A /clock reader, matched with the node's /clock writer."""
    clock = reader(peer, "rt/clock", msg.Clock)
    wait_until(lambda: msg.matched(clock) and msg.matched(node.clock_writer),
               "the /clock reader did not match")
    return clock


def test_clock_is_published_every_tick_with_the_joint_state_stamp():
    node, peer = start(140, publish_rate=100.0)
    clock = clock_reader(node, peer)
    for _ in range(5):
        node.tick()
    states = peer.read(peer.joint_states, 5, msg.JointState)
    clocks = peer.read(clock, 5, msg.Clock)
    assert [c.clock.sec * 10**9 + c.clock.nanosec for c in clocks] == [stamp(m) for m in states]


def test_publish_clock_false_publishes_no_clock():
    node, peer = start(141, publish_clock=False)
    clock = clock_reader(node, peer)
    node.tick()
    peer.read(peer.joint_states, 1, msg.JointState)
    time.sleep(0.05)
    assert [s for s in clock.take(N=10) if isinstance(s, msg.Clock)] == []


def test_joint_state_effort_commands_drive_the_arm_by_joint_name():
    node, peer = start(142, policy="command", gravity=0.0)
    writer = joint_command_writer(peer)
    writer.write(effort_command(["elbow_joint", "shoulder_joint"], [0.25, 1.0]))
    assert node.take_commands(timeout=TIMEOUT) == 1
    assert node.core.command == (1.0, 0.25)
    writer.write(msg.JointState(name=["shoulder_joint"], position=[0.3]))   # ignored: effort
    assert node.take_commands(timeout=TIMEOUT) == 1
    assert node.core.refused_commands == 0 and node.core.command == (1.0, 0.25)
    writer.write(msg.JointState(name=["shoulder_joint"], effort=[80.0]))    # beyond the limit
    assert node.take_commands(timeout=TIMEOUT) == 1
    assert node.core.refused_commands == 1 and node.core.command == (1.0, 0.25)


def test_lockstep_ticks_once_per_command_and_never_on_its_own():
    node, peer = start(143, policy="command", lockstep=True, publish_rate=100.0)
    assert node.tick() is None and node.core.sim.steps == 0        # the timer does not step
    for k in range(3):
        peer.commands.write(msg.Float64MultiArray(data=[0.5 * k, 0.0]))
    deadline, taken = time.monotonic() + TIMEOUT, 0
    while taken < 3 and time.monotonic() < deadline:
        taken += node.take_commands(timeout=0.1)
    states = peer.read(peer.joint_states, 3, msg.JointState)
    assert node.core.sim.time == pytest.approx(0.03)               # three ticks, no more
    assert [stamp(m) for m in states] == [5_000_000_000 + 10_000_000 * (k + 1) for k in range(3)]


def lockstep_core(clock, **parameters):
    return ArmSimCore(resolve_parameters({"policy": "command", "lockstep": True} | parameters),
                      logging.getLogger("test_lockstep"), wall_clock=clock, start_stamp_ns=0)


def test_lockstep_ticks_are_never_late_however_far_apart_the_commands_come():
    clock = FakeClock()
    core = lockstep_core(clock, publish_rate=100.0)
    for _ in range(10):
        clock.now += 0.05                       # a command every 50 ms: five periods apart
        core.on_command([0.5, 0.0])
    assert len(core.lockstep.take()) == 1 + 10 and core.late_ticks == 0
    assert core.diagnostics().level == OK


def test_lockstep_wait_ticks_on_its_own_only_once_no_tick_came_for_that_long():
    """controller_manager under use_sim_time sends nothing until /clock has moved (and a
    period more): a lockstep node that only waited would deadlock with it. The default wait
    is not zero, so no launch has to know of it; it runs while a node listens on /clock."""
    clock = FakeClock()
    core = lockstep_core(clock)
    assert core.config.values["lockstep_wait"] == 0.1
    listened = dict(clock_listened=True)
    assert core.tick(**listened) is not None and core.sim.time == pytest.approx(0.01)  # start
    clock.now += 0.09
    assert core.tick(**listened) is None
    clock.now += 0.01
    assert core.tick(**listened) is not None and core.sim.time == pytest.approx(0.02)  # 0.1 s
    clock.now += 0.05
    core.on_command([0.5, 0.0])                 # a command ticks, and the wait starts again
    clock.now += 0.09
    assert core.tick(**listened) is None and core.sim.time == pytest.approx(0.03)
    clock.now += 1e6                            # nobody on /clock: commands only
    assert core.tick() is None and core.sim.time == pytest.approx(0.03)
    never = lockstep_core(clock, lockstep_wait=0.0)     # 0: commands only, listened or not
    clock.now += 1e6
    assert never.tick(**listened) is None and never.sim.steps == 0


def test_a_lockstep_tick_writes_its_clock_after_its_joint_state_with_no_wall_wait():
    """/clock says the state of its time is out (controller_manager wakes on it and reads
    the latest state): written after it, at once; no wall-clock sleep orders them."""
    node, peer = start(149, policy="command", lockstep=True, lockstep_wait=0.0)
    clock = clock_reader(node, peer)
    for _ in range(3):
        peer.send(node, [0.5, 0.0])
    states = peer.read(peer.joint_states, 3, msg.JointState)
    clocks = [c for c in peer.read(clock, 3, msg.Clock) if stamp_of(c) > 5_000_000_000]
    assert [stamp_of(c) for c in clocks] == [stamp(s) for s in states]
    for state, tick in zip(states, clocks):
        ahead = tick.sample_info.source_timestamp - state.sample_info.source_timestamp
        assert 0 <= ahead < 0.5e6            # ns: a write apart (it slept 1 ms before)


def stamp_of(clock) -> int:
    return clock.clock.sec * 10**9 + clock.clock.nanosec


def test_an_all_nan_joint_state_ticks_a_lockstep_node_and_commands_nothing():
    """ros2_control's hardware interface sends NaN on every command interface no controller
    claims; controller_manager's next cycle waits for the tick it asks for, so a controller
    switch (which takes a cycle) could not happen while none is active (seen on 4.46)."""
    core = lockstep_core(FakeClock(), publish_rate=100.0)
    core.on_command([2.0, 1.0])
    nan = float("nan")
    names = ["shoulder_joint", "elbow_joint"]
    assert core.on_joint_state_command(names, [], [], [nan, nan]) is None
    assert len(core.lockstep.take()) == 1 + 2 and core.command == (2.0, 1.0)
    assert core.refused_commands == 0


@pytest.mark.parametrize("wait", [-0.1, float("nan"), float("inf"), 1e9])
def test_lockstep_wait_is_a_bounded_wall_time(wait):
    with pytest.raises(ParameterRefused, match="lockstep_wait"):
        resolve_parameters({"lockstep_wait": wait})


@pytest.mark.parametrize("real_time_factor", [0.0, 1.0])
def test_the_tick_timer_of_a_lockstep_node_returns_at_once(real_time_factor):
    """The rclpy transport's timer callback (TickSchedule.run_due): in lockstep the commands
    tick, so it returns without looping (it spun for CATCH_UP at real_time_factor 0)."""
    clock, reads = FakeClock(), []

    def wall_clock():                           # each read takes a millisecond
        reads.append(clock.now)
        clock.now += 0.001
        return clock.now

    core = lockstep_core(wall_clock, real_time_factor=real_time_factor)
    schedule = TickSchedule(clock.now)
    reads.clear()
    assert schedule.run_due(core, core.tick) == 0 and reads == []
    core.config = core.config.with_changes({"lockstep": False})
    assert schedule.run_due(core, core.tick) >= 1 and core.sim.steps > 0   # free-running


def test_topics_are_parameters_chosen_at_start():
    node = DdsArmSimNode({"joint_states_topic": "robot_joint_states",
                          "joint_commands_topic": "robot_joint_command"}, domain_id=144,
                         config=CONFIG, wall_clock=lambda: 0.0, start_stamp_ns=0)
    peer = Peer(144)
    states = reader(peer, "rt/robot_joint_states", msg.JointState)
    writer = joint_command_writer(peer, "rt/robot_joint_command")
    writer.write(effort_command(["shoulder_joint", "elbow_joint"], [1.0, 0.0]))
    assert node.take_commands(timeout=TIMEOUT) == 1
    node.tick()
    assert len(peer.read(states, 1, msg.JointState)) == 1
    with pytest.raises(ParameterRefused, match="chosen at start"):
        node.core.set_parameters({"joint_states_topic": "other"})


def test_a_second_node_with_the_same_name_is_warned_about(caplog):
    import logging
    first = DdsArmSimNode({}, domain_id=145, config=CONFIG, wall_clock=lambda: 0.0,
                          start_stamp_ns=0, log=logging.getLogger("first"))
    with caplog.at_level(logging.WARNING):
        time.sleep(0.1)
        first.name_watch.check()                          # alone: its own entry is not a twin
    assert not [r for r in caplog.records if "another node" in r.message]
    second = DdsArmSimNode({}, domain_id=145, config=CONFIG, wall_clock=lambda: 0.0,
                           start_stamp_ns=0, log=logging.getLogger("second"))
    with caplog.at_level(logging.WARNING):
        def noticed():
            first.name_watch.check()
            second.name_watch.check()
            return [r for r in caplog.records if "another node named /arm_sim" in r.message]

        wait_until(noticed, "the twin was not noticed", poll=0.01)
        warned = len(caplog.records)
        first.name_watch.check()
        assert len(caplog.records) == warned               # once per twin, not every second
    first.close()
    second.close()
