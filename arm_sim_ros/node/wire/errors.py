"""What the ROS 2 wire refuses, said in one line before Cyclone DDS says it in a traceback.

Topic names follow rcl's rules (rcl_validate_topic_name, then rmw's for the expanded name):
letters, digits, '_' and '/', no '//', no trailing '/', no part starting with a digit, at
most 247 characters. `~` and `{}` substitutions need a node to expand them; they are refused
here, where the full name is wanted. A configuration Cyclone refuses (CYCLONEDDS_URI) is
reported with Cyclone's own reason, which it would otherwise print on stderr by itself.
"""
import os
import re
import socket
import sys
import tempfile
from contextlib import contextmanager

from ...usage import UsageError

TOPIC_NAME_MAX = 247   # rmw's RMW_TOPIC_MAX_NAME_LENGTH (255 less room for its prefixes)


class DiscoveryError(UsageError):
    """A name or an environment variable that rmw would also reject: one line, exit 2."""


def topic_name_problem(name: str):
    """Why rcl would refuse `name` as a topic name, or None."""
    if not name:
        return "is empty"
    for c in name:
        if c in "~{}":
            return (f"contains {c!r}: substitutions (~, {{node}}) are not expanded here; "
                    "give the full name")
        if not (c.isascii() and (c.isalnum() or c in "_/")):
            return f"contains {c!r}: a topic name has only letters, digits, '_' and '/'"
    if "//" in name:
        return "contains '//'"
    if name.endswith("/"):
        return "ends with '/'"
    if any(part[:1].isdigit() for part in name.split("/")):
        return "has a part that starts with a digit"
    if len("/" + name.lstrip("/")) > TOPIC_NAME_MAX:
        return f"is longer than {TOPIC_NAME_MAX} characters"
    return None


def check_topic_name(name: str, what: str = "topic name") -> str:
    """`name` if rcl accepts it, else DiscoveryError saying why."""
    problem = topic_name_problem(name)
    if problem:
        raise DiscoveryError(f"{what} {name!r} {problem}")
    return name


@contextmanager
def cyclone_messages():
    """Hold back what Cyclone prints on stderr (fd 2) while the block runs; yields a list
    that then holds the text. The caller replays it when nothing went wrong."""
    held_text = []
    with tempfile.TemporaryFile() as held:
        sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(held.fileno(), 2)
        try:
            yield held_text
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            held.seek(0)
            held_text.append(held.read().decode(errors="replace"))


def cyclone_reason(text: str) -> str:
    """Cyclone's first two complaints, without their timestamp and thread prefixes."""
    found = [m.group(1).strip() for m in re.finditer(r"\[\d+\]\s+\S+: (.+)", text)]
    return "; ".join(found[:2]) or " ".join(text.split())[:200] or "no reason given"


def refused_configuration(env_uri: str, explicit: bool, reason: str) -> DiscoveryError:
    if explicit:
        return DiscoveryError(f"Cyclone DDS refuses the configuration it was given ({reason})")
    if env_uri:
        return DiscoveryError(f"CYCLONEDDS_URI={env_uri!r} is a configuration Cyclone DDS "
                              f"refuses ({reason}); fix it or unset CYCLONEDDS_URI")
    return DiscoveryError(f"Cyclone DDS refuses the configuration built from ROS_STATIC_PEERS "
                          f"and ROS_AUTOMATIC_DISCOVERY_RANGE ({reason}); fix or unset them")


def static_peers(env) -> list:
    """ROS_STATIC_PEERS as a list of hosts, each checked: Cyclone aborts the whole process
    (SIGABRT, no message) on a peer it cannot resolve, or an IPv6 one while it runs on
    IPv4 (its default), so those are refused here."""
    peers = [p.strip() for p in env.get("ROS_STATIC_PEERS", "").split(";") if p.strip()]
    for peer in peers:
        try:
            socket.getaddrinfo(peer, None, socket.AF_INET)
        except (socket.gaierror, UnicodeError, ValueError):
            raise DiscoveryError(f"ROS_STATIC_PEERS: {peer!r} is not an IPv4 address or a host "
                                 "name this machine can resolve; list peers as host;host") from None
    return peers
