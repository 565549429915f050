"""One Cyclone DDS C library per symbol scope, checked before cyclonedds (PyPI) loads its own.

ROS 2's rmw_cyclonedds_cpp brings libddsc.so.0 (Cyclone 0.10); the cyclonedds wheel brings
libddsc-<hash>.so.11. Both export the same ~670 dds_/ddsrt_/ddsi_ names, unversioned, and
call their own exported functions through the PLT. Each is loaded RTLD_LOCAL (rclpy's
rmw_implementation, Python's extension loader), so each binds to itself and the two live
side by side. But once one of them is in the process's global scope (LD_PRELOAD, or a plugin
Cyclone dlopens RTLD_GLOBAL with libddsc as its DT_NEEDED: the DDS Security plugins of
SROS2), a libddsc loaded after it binds its own calls to the other's (ddsrt_malloc from one,
ddsrt_free from the other): a segfault or a corrupted heap. docs/guides/reliability.md, "At exit".
"""
from __future__ import annotations

import ctypes
import importlib.util
import os

from ...usage import UsageError
from .errors import DiscoveryError

# setup.py's pin of the cyclonedds package (a test checks that they agree): what to install
# where it is missing (a colcon build installs what rosdep supplies, and rosdep has no key
# for the PyPI package).
CYCLONEDDS = "cyclonedds==11.0.1"


class CycloneMissing(UsageError):
    """The dds transport without the cyclonedds package: one line saying what to install."""


def require_cyclonedds(what: str | None = None) -> None:
    """CycloneMissing where the cyclonedds package cannot be imported; call before the first
    import of it (`what`: the command), so that the person reads what to install, not a
    ModuleNotFoundError."""
    try:
        missing = importlib.util.find_spec("cyclonedds") is None
    except (ImportError, ValueError):       # a broken install: as good as missing
        missing = True
    if missing:
        who = f"{what} runs on the dds transport, which needs" if what else \
            "the dds transport needs"
        raise CycloneMissing(f"{who} the cyclonedds package, not installed here (a colcon "
                             f"build does not install it): pip install {CYCLONEDDS}")


class _DlInfo(ctypes.Structure):
    _fields_ = [("dli_fname", ctypes.c_char_p), ("dli_fbase", ctypes.c_void_p),
                ("dli_sname", ctypes.c_char_p), ("dli_saddr", ctypes.c_void_p)]


def global_cyclone() -> str | None:
    """The file of the Cyclone DDS C library in this process's global symbol scope, if any."""
    try:
        process = ctypes.CDLL(None)       # dlopen(NULL): lookups search the global scope
        address = ctypes.cast(process.dds_create_participant, ctypes.c_void_p).value
    except (AttributeError, OSError):
        return None
    info = _DlInfo()
    for owner in (process, "libdl.so.2"):  # dladdr is in libc from glibc 2.34, in libdl before
        try:
            dladdr = (owner if isinstance(owner, ctypes.CDLL) else ctypes.CDLL(owner)).dladdr
        except (AttributeError, OSError):
            continue
        if dladdr(ctypes.c_void_p(address), ctypes.byref(info)) and info.dli_fname:
            return os.path.realpath(os.fsdecode(info.dli_fname))
    return "an unnamed library"


def own_library_dirs() -> list:
    """Where the cyclonedds package takes its C library from: the wheel's cyclonedds.libs,
    or CYCLONEDDS_HOME/lib for a build against a Cyclone of one's own."""
    dirs = []
    spec = importlib.util.find_spec("cyclonedds")     # finds it without importing it
    if spec is not None and spec.origin:
        dirs.append(os.path.join(os.path.dirname(spec.origin), os.pardir, "cyclonedds.libs"))
    if os.environ.get("CYCLONEDDS_HOME"):
        dirs.append(os.path.join(os.environ["CYCLONEDDS_HOME"], "lib"))
    return [os.path.realpath(d) for d in dirs]


def refuse_foreign_cyclone(found=global_cyclone) -> None:
    """DiscoveryError (one line, exit 2) when another Cyclone DDS is in the global scope: the
    cyclonedds package would bind to it and crash. Call before cyclonedds is first imported."""
    path = found()
    if path is None or os.path.dirname(path) in own_library_dirs():
        return
    raise DiscoveryError(f"another Cyclone DDS C library is loaded globally in this process "
                         f"({path}: LD_PRELOAD, or ROS 2 security plugins); the dds transport's "
                         "cyclonedds would bind to it and crash. Run it in a process of its own "
                         "without it (or use the rclpy transport)")
