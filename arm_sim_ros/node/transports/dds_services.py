"""The node's ROS 2 services on the dds transport, as rmw_cyclonedds (Jazzy) serves them: the
rcl_interfaces parameter services, `~/reset` (std_srvs/srv/Trigger) and `/parameter_events`.

How rmw_cyclonedds lays a service out (rmw_cyclonedds_cpp/src/rmw_node.cpp, Jazzy):
- a reader of `rq/<service>Request` and a writer of `rr/<service>Reply` (rmw_init_cs,
  make_fqtopic with the prefixes of namespace_prefix.hpp), e.g. `rq/arm_sim/get_parametersRequest`;
- each sample starts with `{uint64 guid; int64 seq}`: the client writes its request writer's
  instance handle and a sequence number (rmw_send_request); the service echoes both in the
  reply (rmw_send_response) and the client keeps replies whose guid is its own
  (rmw_take_response);
- QoS as create_readwrite_qos maps the ROS profile (parameter services: rmw_qos_profile_parameters,
  reliable, volatile, keep-last 1000; reset: services default, keep-last 10), autodispose off,
  USER_DATA `serviceid=<id>;typehash=RIHS01_…;` on both endpoints; clients put `clientid=<id>;`;
- a reply goes out only once the reply writer has matched the reader of the client that asked
  (check_for_response_reader); rmw blocks up to 100 ms for that, this keeps the reply pending
  and retries at every poll for up to REPLY_WAIT seconds;
- `ros_discovery_info` lists the request reader among the node's readers and the reply writer
  among its writers (rmw_dds_common Context::add_service_graph).
`/arm_sim/get_type_description` (type_description_interfaces) is not served.
"""
from __future__ import annotations

import time

from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from ...interface import split_stamp
from ..wire import messages as msg
from ..services import parameter_services as ps
from ..params.ros_args import full_node_name
from ..wire.errors import check_topic_name
from . import dds_service_types as t
from . import dds_action, dds_simulation
from .dds_simulation import DdsSimulation

# every service and topic type served here: its ROS name and RIHS01 hash
ROS_TYPE_NAMES = t.ROS_TYPE_NAMES | dds_simulation.ROS_TYPE_NAMES | dds_action.ROS_TYPE_NAMES
TYPE_HASHES = t.TYPE_HASHES | dds_simulation.TYPE_HASHES | dds_action.TYPE_HASHES

REPLY_WAIT = 2.0          # s a reply waits for its client's reply reader to be matched
PARAMETERS_DEPTH = 1000   # rmw_qos_profile_parameters / rmw_qos_profile_parameter_events
WAIT_SLICE = 0.1          # s a wait blocks at most (Python handles signals between waits)
_ANY = SampleState.Any | ViewState.Any | InstanceState.Any


def endpoint_qos(message_type, depth: int, user_data: str = "") -> Qos:
    """rmw_cyclonedds' create_readwrite_qos for reliable, volatile, keep-last `depth`."""
    typehash = TYPE_HASHES[ROS_TYPE_NAMES[message_type]]
    return Qos(Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
               Policy.Durability.Volatile, Policy.History.KeepLast(depth),
               Policy.WriterDataLifecycle(autodispose=False),
               Policy.Userdata(f"{user_data}typehash={typehash};".encode()))


def user_data_value(qos, key: str) -> str | None:
    """A `key=value;` entry of an endpoint's USER_DATA (rmw's parse_user_data), or None."""
    try:
        data = qos[Policy.Userdata].data
    except (KeyError, TypeError):
        return None
    for entry in data.split(b";"):
        name, equals, value = entry.partition(b"=")
        if equals and name.decode(errors="replace") == key:
            return value.decode(errors="replace")
    return None


def cs_id(participant_guid: bytes, counter: int) -> str:
    """rmw_cyclonedds' client/service id (get_unique_csid, csid_to_string): the participant's
    GUID prefix and a big-endian counter, printed in hex, the first byte padded to width 2."""
    data = participant_guid[:12] + counter.to_bytes(4, "big")
    return f"{data[0]:2x}" + "".join(f".{b:x}" for b in data[1:])


def _matched_subscriptions(writer) -> list:
    return _matched(writer.get_matched_subscriptions)


def _matched(handles) -> list:
    for _ in range(100):   # cyclonedds-python 11.0.1 races a match arriving mid-copy (IndexError)
        try:
            return handles()
        except IndexError:
            continue
    return []


class ServiceEndpoint:
    """One service: its request reader, its reply writer, and the handler that turns a request
    into the reply's fields."""

    def __init__(self, participant, name: str, request_type, reply_type, handler, depth: int,
                 service_id: str):
        self.name, self.reply_type, self.handler = name, reply_type, handler
        user_data = f"serviceid={service_id};"
        self.reader = DataReader(
            participant, Topic(participant, f"rq{name}Request", request_type),
            qos=endpoint_qos(request_type, depth, user_data))
        self.writer = DataWriter(
            participant, Topic(participant, f"rr{name}Reply", reply_type),
            qos=endpoint_qos(reply_type, depth, user_data))
        self.request_type = request_type
        self.condition = ReadCondition(self.reader, _ANY)
        self._matches, self._ready = None, set()   # client_state's: clients ready while matched

    def take(self, log=None) -> list:
        """(reply, the asking writer's instance handle) for every request waiting. A request
        the handler cannot answer is logged and left unanswered: the simulation goes on."""
        answered = []
        try:
            requests = self.reader.take(N=64)
        except Exception as error:   # noqa: BLE001 - bytes that do not decode as the request
            if log is not None:
                log.error(f"{self.name}: unreadable request dropped: {error!r}")
            return answered
        for request in requests:
            if not isinstance(request, self.request_type):  # InvalidSample: lifecycle only
                continue
            try:
                fields = self.handler(request)
            except Exception as error:   # noqa: BLE001 - a bad request must not stop the node
                if log is not None:
                    log.error(f"{self.name}: request {request.seq} not answered: {error!r}")
                continue
            if fields is None:           # answered later (an action's result: reply_later)
                continue
            reply = self.reply_type(guid=request.guid, seq=request.seq, **fields)
            answered.append((reply, request.sample_info.publication_handle))
        return answered

    def client_state(self, client_writer: int) -> str:
        """'ready' when the reply writer has matched the reader of the client whose request
        writer is `client_writer`, 'gone' when that writer has left, else 'waiting'. A ready
        client stays ready while the matches stand: cyclonedds-python 11.0.1 leaks ~100 B
        per get_matched_*_data (~0.4 kB a request, without end under 200 sets/s)."""
        matches = (tuple(_matched(self.reader.get_matched_publications)),
                   tuple(_matched_subscriptions(self.writer)))
        if matches != self._matches:
            self._matches, self._ready = matches, set()
        if client_writer in self._ready:
            return "ready"
        state = self._client_state(client_writer)
        if state == "ready":
            self._ready.add(client_writer)
        return state

    def _client_state(self, client_writer: int) -> str:
        try:
            writer = self.reader.get_matched_publication_data(client_writer)
        except Exception:        # noqa: BLE001 - cyclonedds raises for a handle it no longer knows
            writer = None
        if writer is None:
            return "gone"
        client = user_data_value(writer.qos, "clientid")
        if client is None:       # a client that does not say who it is: rmw assumes all is well
            return "ready"
        for handle in _matched_subscriptions(self.writer):
            reader = self.writer.get_matched_subscription_data(handle)
            if reader is not None and user_data_value(reader.qos, "clientid") == client:
                return "ready"
        return "waiting"


class DdsServices:
    """The parameter services, ~/reset and /parameter_events of one node on `participant`.
    Create before announcing the node (its endpoints belong in ros_discovery_info), `attach`
    the core, then `poll()` from the loop or `serve_for(seconds)` instead of sleeping."""

    def __init__(self, participant, name: str, namespace: str, log, resolve,
                 clock_ns=time.time_ns):
        """`resolve(ros_name)`: a service or topic name expanded and remapped as rcl does
        (`~/reset` is `/<namespace>/<name>/reset` unless a `-r` rule says otherwise)."""
        self.node = full_node_name(name, namespace)
        self.log, self.clock_ns = log, clock_ns
        self.core = self.parameters = None
        self.events_writer = DataWriter(
            participant, Topic(participant, msg.ros_topic(resolve("/parameter_events")),
                               t.ParameterEvent),
            qos=endpoint_qos(t.ParameterEvent, PARAMETERS_DEPTH))
        guid = participant.guid.bytes
        services = (
            ("list_parameters", t.ListParametersRequest, t.ListParametersResponse, self._list),
            ("get_parameters", t.GetParametersRequest, t.GetParametersResponse, self._get),
            ("set_parameters", t.SetParametersRequest, t.SetParametersResponse, self._set),
            ("set_parameters_atomically", t.SetParametersAtomicallyRequest,
             t.SetParametersAtomicallyResponse, self._set_atomically),
            ("describe_parameters", t.DescribeParametersRequest, t.DescribeParametersResponse,
             self._describe),
            ("get_parameter_types", t.GetParameterTypesRequest, t.GetParameterTypesResponse,
             self._types),
            ("reset", t.TriggerRequest, t.TriggerResponse, self._reset),
        )
        # the Simulation Interfaces, under the node's namespace (not ~/): dds_simulation.py
        self.simulation = DdsSimulation()
        self.action = dds_action.DdsSimulateSteps(participant, resolve, clock_ns)
        services = ([(f"~/{name}", *rest) for name, *rest in services]
                    + self.simulation.services() + self.action.services())
        self.endpoints = [
            ServiceEndpoint(participant, check_topic_name(resolve(service), "service name"),
                            request, reply, handler,
                            # every service keeps as many as the parameter services, so
                            # that a burst of 200/s (~/reset) loses none between two polls
                            PARAMETERS_DEPTH,
                            cs_id(guid, index + 1))
            for index, (service, request, reply, handler) in enumerate(services)]
        self.waitset = WaitSet(participant)
        for endpoint in self.endpoints:
            self.waitset.attach(endpoint.condition)
        self.pending = []         # (endpoint, reply, client writer handle, give up at)

    @property
    def readers(self) -> list:
        return [endpoint.reader for endpoint in self.endpoints]

    @property
    def writers(self) -> list:
        return ([self.events_writer] + [endpoint.writer for endpoint in self.endpoints]
                + self.action.writers)

    def attach(self, core, control=None) -> None:
        """Serve `core`'s parameters; announce them as new, as rclpy does when it declares them.
        `control`: the SimulationControl the Simulation Interfaces drive."""
        self.core, self.simulation.control = core, control
        self.simulation.reply_later = self.reply_later
        if control is not None:
            self.action.attach(control, self.reply_later)
            control.goal_running = lambda: self.action.busy
        self.log = core.log if self.log is None else self.log
        self.parameters = ps.ParameterServices(core, self.log, self._publish_event)
        self._publish_event(new=[spec.name for spec in ps.PARAMETERS])

    # the loop ---------------------------------------------------------------------------

    def poll(self) -> int:
        """Answer every request waiting and retry pending replies; returns replies sent. A
        SimulateSteps goal executing (dds_action.py) or a step_simulation call takes one
        tick first."""
        self.action.advance()
        self.simulation.advance()
        if not self.pending and not self.waitset.wait(0):
            return 0
        now = time.monotonic()
        for endpoint in self.endpoints:
            for reply, client in endpoint.take(self.log):
                self.pending.append((endpoint, reply, client, now + REPLY_WAIT))
        sent, still = 0, []
        for endpoint, reply, client, give_up in self.pending:
            state = endpoint.client_state(client)
            if state == "ready":
                endpoint.writer.write(reply)
                sent += 1
            elif state == "waiting" and now < give_up:
                still.append((endpoint, reply, client, give_up))
            elif state == "waiting":
                self.log.warning(f"{endpoint.name}: the client's reply reader never matched "
                                 f"in {REPLY_WAIT:g} s; reply {reply.seq} dropped")
        self.pending = still
        return sent

    def serve_for(self, seconds: float) -> None:
        """Wait `seconds` (wall time), answering requests as they arrive."""
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            busy = self.action.busy or self.simulation.busy
            wait = min(left, 0.0 if busy else 0.005 if self.pending
                       else WAIT_SLICE)                             # signals between waits
            self.waitset.wait(duration(seconds=wait))
            self.poll()

    def reply_later(self, service: str, reply, request) -> None:
        """Send `reply` to the client of `request`, taken earlier, once its reader matches."""
        endpoint = next(e for e in self.endpoints if e.name.endswith(service))
        self.pending.append((endpoint, reply, request.sample_info.publication_handle,
                             time.monotonic() + REPLY_WAIT))

    def close(self) -> None:
        for endpoint in self.endpoints:
            self.waitset.detach(endpoint.condition)
        self.endpoints, self.pending = [], []
        self.waitset = self.events_writer = None
        self.action.close()

    # handlers: request -> the reply's fields -----------------------------------------------

    def _list(self, request) -> dict:
        names, prefixes = self.parameters.list(list(request.prefixes), request.depth)
        return {"result": t.ListParametersResult(names=names, prefixes=prefixes)}

    def _get(self, request) -> dict:
        return {"values": [to_value(*tv) for tv in self.parameters.get(list(request.names))]}

    def _types(self, request) -> dict:
        return {"types": self.parameters.types(list(request.names))}

    def _describe(self, request) -> dict:
        return {"descriptors": [
            t.ParameterDescriptor(name=d.name, type=d.type, description=d.description,
                                  read_only=d.read_only, dynamic_typing=d.dynamic_typing)
            for d in self.parameters.describe(list(request.names))]}

    def _set(self, request) -> dict:
        results = self.parameters.set_each([from_parameter(p) for p in request.parameters])
        return {"results": [t.SetParametersResult(r.successful, r.reason) for r in results]}

    def _set_atomically(self, request) -> dict:
        result = self.parameters.set_atomically([from_parameter(p) for p in request.parameters])
        return {"result": t.SetParametersResult(result.successful, result.reason)}

    def _reset(self, request) -> dict:
        success, message = self.parameters.reset()
        return {"success": success, "message": message}

    def _publish_event(self, changed=(), new=()) -> None:
        sec, nanosec = split_stamp(self.clock_ns())

        def parameter(name):
            return t.Parameter(name, to_value(*self.parameters.value(name)))

        self.events_writer.write(t.ParameterEvent(
            stamp=msg.Time(sec, nanosec), node=self.node,
            new_parameters=[parameter(n) for n in new],
            changed_parameters=[parameter(n) for n in changed]))


# ParameterValue <-> (type, Python value) -------------------------------------------------------

_FIELDS = {ps.BOOL: "bool_value", ps.INTEGER: "integer_value", ps.DOUBLE: "double_value",
           ps.STRING: "string_value", ps.BYTE_ARRAY: "byte_array_value",
           ps.BOOL_ARRAY: "bool_array_value", ps.INTEGER_ARRAY: "integer_array_value",
           ps.DOUBLE_ARRAY: "double_array_value", ps.STRING_ARRAY: "string_array_value"}


def to_value(kind: int, value) -> t.ParameterValue:
    if kind == ps.NOT_SET:
        return t.ParameterValue()
    if kind == ps.DOUBLE:
        value = float(value)
    elif kind == ps.DOUBLE_ARRAY:
        value = [float(v) for v in value]
    elif kind in (ps.BYTE_ARRAY, ps.BOOL_ARRAY, ps.INTEGER_ARRAY, ps.STRING_ARRAY):
        value = list(value)
    return t.ParameterValue(type=kind, **{_FIELDS[kind]: value})


def from_value(value: t.ParameterValue):
    """The Python value a ParameterValue carries (None for NOT_SET or an unknown type)."""
    field_name = _FIELDS.get(value.type)
    if field_name is None:
        return None
    carried = getattr(value, field_name)
    return list(carried) if isinstance(carried, (list, tuple, bytes)) else carried


def from_parameter(parameter: t.Parameter) -> tuple:
    return parameter.name, from_value(parameter.value)
