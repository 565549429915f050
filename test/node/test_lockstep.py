"""Lockstep, a closed loop ordered by its messages (node/schedule.py Lockstep): every state
published awaits the command that answers it, named by the state's stamp, and a tick happens
when, and only when, that command has come and the simulation may move. No wall clock
orders anything. DDS tests: loopback, domains 170-179."""
import logging
import math

import pytest

from arm_sim_ros.node.core import ArmSimCore
from arm_sim_ros.node.schedule import Lockstep
from arm_sim_ros.node.params.parameters import resolve_parameters
from arm_sim_ros.node.services import simulation as s
from arm_sim_ros.node.services.simulation import SimulationControl
from arm_sim_ros.node.transports.dds import lockstep_idle
from arm_sim_ros.node.wire import messages as msg
from node.test_node_dds import FakeClock, Peer, start, wait_until

NAMES = ["shoulder_joint", "elbow_joint"]
ORIGIN = 5_000_000_000


def core_in_lockstep(**parameters):
    values = {"policy": "command", "lockstep": True, "lockstep_wait": 0.0} | parameters
    return ArmSimCore(resolve_parameters(values), logging.getLogger("test_lockstep"),
                      wall_clock=FakeClock(), start_stamp_ns=ORIGIN)


def answer(core, stamp_ns, effort=(1.0, -0.5)):
    return core.on_joint_state_command(NAMES, [], [], list(effort), stamp_ns)


def stamps(states):
    return [state.stamp_ns for state in states]


def test_a_lockstep_node_publishes_the_state_its_first_command_answers_once():
    core = core_in_lockstep()
    assert stamps(core.lockstep.take()) == [ORIGIN]
    assert core.lockstep.take() == [] and core.sim.steps == 0


def test_the_answer_to_the_latest_state_ticks_and_its_tick_awaits_the_next():
    core = core_in_lockstep(publish_rate=100.0)
    core.lockstep.take()
    answer(core, ORIGIN)
    assert stamps(core.lockstep.take()) == [ORIGIN + 10_000_000]
    assert core.command == (1.0, -0.5)
    answer(core, ORIGIN + 10_000_000, (2.0, 0.0))
    assert stamps(core.lockstep.take()) == [ORIGIN + 20_000_000]


def test_a_second_answer_to_a_state_is_stale_neither_taken_nor_ticked():
    """A state answered twice (sent again to a reader that joined, or a second controller):
    the later answer names a state no longer the latest."""
    core = core_in_lockstep()
    core.lockstep.take()
    answer(core, ORIGIN, (1.0, 0.0))
    core.lockstep.take()
    assert answer(core, ORIGIN, (9.0, 9.0)) is None
    assert core.lockstep.take() == [] and core.sim.steps == 1
    assert core.command == (1.0, 0.0) and core.stale_commands == 1
    assert dict(core.diagnostics().values)["stale_commands"] == "1"


@pytest.mark.parametrize("stamp", [0, 1_795_000_000_000_000_000], ids=["unstamped", "wall"])
def test_a_command_whose_stamp_names_no_state_answers_the_latest_on_arrival(stamp):
    """An unstamped JointState, or one stamped by another clock (ros2_control's topic-based
    hardware stamps its own node's time): the latest state, as a Float64MultiArray does."""
    core = core_in_lockstep()
    core.lockstep.take()
    for k in range(3):
        answer(core, stamp)
        core.on_command([0.5, 0.0])
    assert len(core.lockstep.take()) == 6 and core.stale_commands == 0


def test_a_refused_answer_ticks_under_the_last_good_command():
    """The controller answered, badly: the loop goes on (the node never stalls on bad input)
    and the refusal is counted."""
    core = core_in_lockstep(torque_limit=50.0)
    core.lockstep.take()
    answer(core, ORIGIN, (1.0, 2.0))
    latest = core.lockstep.take()[-1].stamp_ns
    assert answer(core, latest, (500.0, 0.0)) is not None
    assert len(core.lockstep.take()) == 1
    assert core.command == (1.0, 2.0) and core.refused_commands == 1


def test_a_paused_node_holds_the_answer_until_it_plays():
    core = core_in_lockstep()
    control = SimulationControl(core, lambda data: None)
    core.lockstep.take()
    control.set_state(s.STATE_PAUSED)
    answer(core, ORIGIN)
    assert core.lockstep.take() == [] and core.sim.steps == 0
    assert core.tick() is None                   # nor the held state again on the timer
    control.set_state(s.STATE_PLAYING)
    assert stamps(core.lockstep.take()) == [ORIGIN + 10_000_000]


def test_step_simulation_in_lockstep_takes_one_answered_tick_at_a_time():
    """A StepSimulation call of 3 ticks, paused: each tick waits for the answer to the state
    before it, however often the node looks (advance is called every loop pass)."""
    published, done = [], []
    core = core_in_lockstep()
    control = SimulationControl(core, published.append)
    core.lockstep.take()
    control.set_state(s.STATE_PAUSED)
    assert control.call_steps(3, lambda *result: done.append(result)) is None
    for k in range(3):
        for _ in range(5):
            assert not control.advance()        # not answered: no tick
        answer(core, ORIGIN + k * 10_000_000)
        assert control.advance()
        assert stamps(published) == [ORIGIN + (j + 1) * 10_000_000 for j in range(k + 1)]
    assert done == [(s.RESULT_OK, "")] and core.sim.steps == 3


def test_lockstep_switched_on_live_awaits_the_answer_to_the_state_it_is_in():
    core = ArmSimCore(resolve_parameters({"policy": "command"}), logging.getLogger("t"),
                      wall_clock=FakeClock(), start_stamp_ns=ORIGIN)
    core.tick()
    core.set_parameters({"lockstep": True})
    assert stamps(core.lockstep.take()) == [ORIGIN + 10_000_000]
    answer(core, ORIGIN + 10_000_000)
    assert stamps(core.lockstep.take()) == [ORIGIN + 20_000_000]


def test_the_awaited_state_goes_again_to_each_reader_that_matches_later():
    """The state published at start went out before anyone listened: a controller that
    joins is sent it when its reader matches (an event of the wire, not a wall-clock
    wait), and one already there is not sent it twice by an idle node."""
    node, peer = start(170, policy="command", lockstep=True, lockstep_wait=0.0)
    node.take_commands()
    lockstep_idle(node, 0.0)
    first = peer.read(peer.joint_states, 1, msg.JointState)
    assert first[0].header.stamp.sec == 5 and first[0].header.stamp.nanosec == 0
    lockstep_idle(node, 0.0)                       # nobody new: nothing sent
    assert [m for m in peer.joint_states.take(N=10) if isinstance(m, msg.JointState)] == []
    late = Peer(170)
    late.wait_matched()
    wait_until(lambda: msg.matched(node.joint_state_writer) == 2, "second reader")
    lockstep_idle(node, 0.0)
    again = late.read(late.joint_states, 1, msg.JointState)
    assert again[0].header == first[0].header and node.core.sim.steps == 0
    # the reader already there hears it a second time, the same stamp: an answer to it after
    # the first is stale (see above), so a controller may answer every copy it hears
    assert peer.read(peer.joint_states, 1, msg.JointState)[0].header == first[0].header


def test_an_unanswered_state_goes_out_again_to_a_new_reader_or_after_a_while():
    """Delivery, not order: a copy of the latest state, the same stamp (an answer to the
    copy after the first is stale), to a reader that matched since it went out, or RESEND s
    after (a reader counted as matched before it could take it). Answered: never."""
    lockstep = Lockstep()
    assert not lockstep.resend(1, 0.0)                       # nothing published yet
    lockstep.latest(type("State", (), {"stamp_ns": 10})())
    assert not lockstep.resend(1, 5.0)                       # just went out: counting from here
    assert lockstep.resend(2, 5.1)                           # a reader more
    assert not lockstep.resend(2, 5.1 + Lockstep.RESEND / 2)
    assert lockstep.resend(2, 5.1 + Lockstep.RESEND)         # unanswered that long
    lockstep.answered = True
    assert not lockstep.resend(3, 100.0)
