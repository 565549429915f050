"""rosgraph_msgs/Clock on the dds transport: /clock as Gazebo publishes it, so that nodes
started with use_sim_time:=true follow the simulation."""
from dataclasses import dataclass, field

from cyclonedds.core import Policy, Qos
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.annotations import final
from cyclonedds.util import duration

from .. import messages as msg

CLOCK_TOPIC = "/clock"
# REP 2011 hash of rosgraph_msgs/msg/Clock as rosidl computes it for Jazzy (test_clock checks
# it against the rosbags library); it goes into the writer's USER_DATA as rmw puts it there.
CLOCK_TYPE_HASH = "RIHS01_692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564"


@final
@dataclass
class Clock(IdlStruct, typename="rosgraph_msgs.msg.dds_.Clock_"):
    clock: msg.Time = field(default_factory=msg.Time)


def clock_message(stamp_ns: int) -> Clock:
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    return Clock(clock=msg.Time(sec, nanosec))


def clock_qos() -> Qos:
    """The ROS default profile (reliable, volatile, keep-last 10): it matches rclcpp's and
    rclpy's best-effort /clock subscriptions as well as reliable ones."""
    return Qos(Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
               Policy.Durability.Volatile, Policy.History.KeepLast(10),
               Policy.Userdata(f"typehash={CLOCK_TYPE_HASH};".encode()))
