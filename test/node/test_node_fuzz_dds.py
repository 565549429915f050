"""Fuzz the whole live parameter surface on the dds transport: every parameter x hostile
values x bursts of set requests (up to 200/s between two ticks), through the node's own
parameter services. Whatever arrives, the node answers every request, keeps ticking with
finite JointStates, and still answers a reset and a later set. (The rclpy transport hands
the same values to the same core: test_node_hostile fuzzes that.) Loopback, domain 204."""
import math
import time

import pytest
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from hypothesis import HealthCheck, example, given, settings, strategies as st

from arm_sim_ros.node.wire import messages as msg
from arm_sim_ros.node.services.parameter_services import (BOOL, DOUBLE, DOUBLE_ARRAY, INTEGER,
                                                          INTEGER_ARRAY, STRING, STRING_ARRAY)
from arm_sim_ros.node.params.parameters import SPECS
from arm_sim_ros.node.transports import dds_service_types as t
from arm_sim_ros.node.transports.dds_services import endpoint_qos, to_value
from node.test_dds_services import Client, start as start_node
from node.test_node_dds import TIMEOUT

INT64 = 2 ** 63 - 1
NUMBERS = [math.nan, math.inf, -math.inf, 0.0, -0.0, -1.0, 1e308, -1e308, 5e-324, 1e-300,
           1e200, 1e-12, 0.001, 0.01, 7.0, 100.0, 1e4]
TEXTS = ["", "x" * 20_000, "rk4", "dopri5", "release", "command", "nonsense", "\n\x00",
         "no/such/dir/../arm.rrd", "arm.rrd", "127.0.0.1:1"]


def wire_value():
    """(ParameterType, value) as a client may put it on the wire, of every type."""
    return st.one_of(
        st.tuples(st.just(DOUBLE), st.sampled_from(NUMBERS)),
        st.tuples(st.just(INTEGER), st.sampled_from([0, 1, -1, 100, INT64, -INT64 - 1])),
        st.tuples(st.just(BOOL), st.booleans()),
        st.tuples(st.just(STRING), st.sampled_from(TEXTS)),
        st.tuples(st.just(DOUBLE_ARRAY), st.lists(st.sampled_from(NUMBERS), max_size=3)),
        st.tuples(st.just(INTEGER_ARRAY), st.lists(st.sampled_from([0, 3, INT64]), max_size=3)),
        st.tuples(st.just(STRING_ARRAY), st.lists(st.sampled_from(TEXTS), max_size=3)))


def own_kind(name):
    """Values of the parameter's own kind: these pass the type checks and reach the physics
    (an arm of 1e200 m passes the check of its numbers, not the build of its mass matrix)."""
    kind = SPECS[name].kind
    numbers = st.sampled_from(NUMBERS)
    if kind in ("float_pair", "float_or_pair"):
        return st.one_of(numbers.map(lambda v: (DOUBLE_ARRAY, [v, v])),
                         st.tuples(st.just(DOUBLE_ARRAY), st.lists(numbers, min_size=2,
                                                                    max_size=2)))
    if kind == "float":
        return st.tuples(st.just(DOUBLE), numbers)
    return wire_value()


requests = st.lists(st.sampled_from(sorted(SPECS)).flatmap(
    lambda name: st.tuples(st.just(name), st.one_of(own_kind(name), wire_value()))),
    min_size=1, max_size=40)


@pytest.fixture(scope="module")
def node_and_clients():
    node, participant = start_node(204, damping=0.5)
    setter = deep_client(participant, "set_parameters")
    reset = deep_client(participant, "reset")
    states = DataReader(participant, Topic(participant, "rt/joint_states", msg.JointState),
                        qos=msg.default_qos(msg.JointState, depth=1000))
    yield node, setter, reset, states
    node.close()


def deep_client(participant, service):
    """A client that keeps every reply (as one taking them at once would)."""
    client = Client(participant, service, reply_reader=False)
    client.reader = DataReader(participant, Topic(participant, f"rr{client.name}Reply",
                                                  client.reply_type),
                               qos=endpoint_qos(client.reply_type, 1000, client.user_data))
    client.wait_for_service()
    return client


def replies(node, client, count):
    received, deadline = [], time.monotonic() + TIMEOUT
    while len(received) < count and time.monotonic() < deadline:
        node.services.poll()
        received += [r for r in client.reader.take(N=1000) if isinstance(r, client.reply_type)]
        time.sleep(0.0005)
    return received


def finite(state):
    return all(math.isfinite(v) for v in list(state.position) + list(state.velocity)
               + list(state.effort))


@pytest.mark.hunt
@settings(max_examples=150, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(burst=requests)
@example(burst=[("controller_model.link_lengths", (DOUBLE_ARRAY, [1e200, 1e200]))])   # the trial's
@example(burst=[("real_time_factor", (DOUBLE, 5e-324)), ("rerun_path", (STRING, "\n\x00"))])
def test_the_node_answers_every_set_and_keeps_ticking_whatever_arrives(node_and_clients, burst,
                                                                       tmp_path_factory):
    node, setter, reset, states = node_and_clients
    states.take(N=1000)
    for name, (kind, value) in burst:          # one burst between two ticks
        if name == "rerun_path" and kind == STRING and value == "arm.rrd":
            value = str(tmp_path_factory.mktemp("rrd") / "arm.rrd")
        setter.send(parameters=[t.Parameter(name, to_value(kind, value))])
    answered = replies(node, setter, len(burst))
    assert len(answered) == len(burst)
    assert all(len(r.results) == 1 and len(r.results[0].reason) < 1000 for r in answered)
    ticked = 0
    for _ in range(3):
        if node.core.config.values["lockstep"]:
            break                                # commands tick then: nothing to publish
        node.tick()
        ticked += 1
    published, deadline = [], time.monotonic() + TIMEOUT
    while len(published) < ticked and time.monotonic() < deadline:
        published += [s for s in states.take(N=1000) if isinstance(s, msg.JointState)]
    assert len(published) == ticked and all(finite(s) for s in published)
    reset.send()
    assert [r.success for r in replies(node, reset, 1)] == [True]
