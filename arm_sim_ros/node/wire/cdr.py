"""sensor_msgs/JointState and rosgraph_msgs/Clock as XCDR1 bytes, written out directly: the
node writes one of each every tick, and the generic cyclonedds serializer costs ~30 us
each, as much as six RK4 steps. A JointState's layout is fixed by its frame_id, names and
sequence lengths, which stay the same from tick to tick: its struct.Struct is built once,
and each message is then one pack. messages.JointState.serialize and messages.Clock.serialize
use these on little-endian machines, and the dds transport writes them with no message built
(transports/dds.py, write_cdr); the bytes are the generic serializer's (test_ros_messages.py). Every
one is a whole number of 4-byte words, as DataWriter.write pads them."""
import sys
from functools import lru_cache
from struct import Struct, pack

LITTLE_ENDIAN = sys.byteorder == "little"
_CDR_LE_HEADER = b"\x00\x01\x00\x00"   # encapsulation: plain CDR (XCDR1), little-endian
_CLOCK = Struct("<4siI")               # the header, then builtin_interfaces/Time


def clock_cdr(sec: int, nanosec: int) -> bytes:
    """XCDR1 of a Clock (its one field, a Time: sec, nanosec)."""
    return _CLOCK.pack(_CDR_LE_HEADER, sec, nanosec)


def joint_state_cdr(message) -> bytes:
    """XCDR1 of a messages.JointState."""
    stamp, header = message.header.stamp, message.header
    return joint_state_bytes(stamp.sec, stamp.nanosec, header.frame_id, message.name,
                             message.position, message.velocity, message.effort)


def joint_state_bytes(sec: int, nanosec: int, frame_id: str, names, p, v, e) -> bytes:
    """XCDR1 of the JointState with these fields (no message built): the header, the stamp,
    the frame_id and names (one field), then each sequence of doubles, its count first."""
    struct, text = _layout(frame_id, tuple(names), len(p), len(v), len(e))
    return struct.pack(_CDR_LE_HEADER, sec, nanosec, text, len(p), *p, len(v), *v, len(e), *e)


@lru_cache(maxsize=16)
def _layout(frame_id: str, names: tuple, *counts: int) -> tuple[Struct, bytes]:
    """(the Struct of a JointState with these strings and sequence lengths, the bytes of its
    frame_id and names). Alignment counts from the CDR origin, the end of the 4-byte
    encapsulation; the stamp takes its first 8 bytes."""
    text = bytearray()

    def string(value):
        data = value.encode() + b"\0"
        text.extend(bytes(-len(text) % 4))
        text.extend(pack("<I", len(data)) + data)

    string(frame_id)
    text.extend(bytes(-len(text) % 4))
    text.extend(pack("<I", len(names)))
    for name in names:
        string(name)
    fields, at = [f"<4siI{len(text)}s"], 8 + len(text)
    for count in counts:               # position, velocity, effort: 4-aligned count, then
        before = -at % 4               # the doubles 8-aligned (no padding when there are none)
        at += before + 4
        within = -at % 8 if count else 0
        at += within + 8 * count
        fields.append(f"{before}xI{within}x{count}d")
    return Struct("".join(fields)), bytes(text)
