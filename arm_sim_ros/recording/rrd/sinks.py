"""Where a Rerun recording goes: a .rrd file, a viewer spawned for it, a viewer already
running at an address. A sink that cannot open is one warning and is skipped; the
simulation runs on.
"""
from __future__ import annotations

import os
import socket
import stat
import struct
import sys
from urllib.parse import urlsplit

import rerun as rr
from rerun import bindings

from ...usage import UsageError
from ..csv_file import let_writes_fail_on_file_size_limit

DEFAULT_PORT = 9876
# A node's file is written without rerun's footer: the footer's manifest keeps ~1 kB per
# chunk in memory until the file closes (a node records for hours; rerun's own advice for
# long streams). rerun's warning of it is silenced in __init__.py.
RRD_HEADER = 12       # an .rrd: 'RRF2', version, options; then messages {kind, length}
RRD_END = 0           # the kind of the end-of-stream marker (the footer follows)


def viewer_url(address: str) -> str:
    """`host:port`, `rerun+http://host:port/proxy` or a bare port -> the gRPC URL rerun takes."""
    text = address.strip()
    if text.isdigit():
        text = f"127.0.0.1:{text}"
    if "://" not in text:
        text = f"rerun+http://{text}/proxy"
    return text


def viewer_reachable(url: str, timeout: float = 0.5) -> bool:
    """A quick TCP check: rerun's own connect blocks ~5 s and then drops data silently."""
    parts = urlsplit(url)
    try:
        with socket.create_connection((parts.hostname or "127.0.0.1", parts.port or DEFAULT_PORT),
                                      timeout=timeout):
            return True
    except (OSError, ValueError):
        return False


def open_sinks(stream, board, opened: list, warn_once, path=None, spawn=False,
               connect=None, footer=True) -> bool:
    """Open the sinks asked for on `stream` with `board` as the default blueprint; True when
    any opened. A description of each sink that opens is appended to `opened`; each failure
    is warn_once(key, message), key "file", "spawn" or "connect", and that sink is skipped.
    `footer`: the file ends in rerun's footer (see above)."""
    sinks = []
    if path:
        let_writes_fail_on_file_size_limit()   # a full file then fails a write: checked at the end
        try:
            open(path, "wb").close()
            sinks.append(rr.FileSink(str(path), write_footer=footer))
            opened.append(f"file {path}")
        except OSError as error:
            warn_once("file", f"rerun: cannot write {path} ({error.strerror}); "
                              "the simulation runs on without that recording")
    if spawn:
        _spawn_viewer(stream, sinks, opened, warn_once)
    if connect:
        url = viewer_url(connect)
        if viewer_reachable(url):
            sinks.append(rr.GrpcSink(url))
            opened.append(f"viewer {url}")
        else:
            warn_once("connect", f"rerun: no viewer answers at {url}; running on "
                                 "without it (start `rerun` first)")
    if sinks:
        bindings.set_sinks(sinks, default_blueprint=blueprint_storage(stream, board),
                           recording=stream.to_native())
    return bool(sinks)


# rerun 0.41 builds every blueprint it sends (rr.set_sinks, rr.send_blueprint) on a new
# native stream that it frees only at exit (rerun#2116): two threads and their buffers per
# blueprint. A node that changes its layout or its file 100 times a second would grow by
# hundreds of threads, so each application's blueprints go through one stream, reused.
_BLUEPRINT_STREAMS: dict = {}


def blueprint_storage(stream, board):
    """`board` as the storage rerun's bindings send, built on the application's one
    blueprint stream (as rerun.blueprint.api.create_in_memory_blueprint builds it)."""
    application_id = stream.get_application_id()
    blueprint_stream = _BLUEPRINT_STREAMS.get(application_id)
    if blueprint_stream is None:
        blueprint_stream = _BLUEPRINT_STREAMS[application_id] = rr.RecordingStream._from_native(
            bindings.new_blueprint(application_id=application_id, make_default=False,
                                   make_thread_default=False, default_enabled=True))
    memory = blueprint_stream.memory_recording()   # the sink this blueprint alone goes to
    blueprint_stream.set_time("blueprint", sequence=0)
    board.to_blueprint()._log_to_stream(blueprint_stream)
    return memory.storage


def send_blueprint(stream, board) -> None:
    """rr.send_blueprint(board, recording=stream) without a new stream per call."""
    bindings.send_blueprint(blueprint_storage(stream, board), True, True,
                            recording=stream.to_native())


def _spawn_viewer(stream, sinks, opened, warn_once) -> None:
    """A viewer on DEFAULT_PORT; rerun only logs when one fails to come up, so check."""
    url = viewer_url(str(DEFAULT_PORT))
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        warn_once("spawn", "rerun: no display to spawn a viewer on (DISPLAY is unset); "
                           "running on without it")
        return
    try:
        rr.spawn(port=DEFAULT_PORT, connect=False, recording=stream)
    except Exception as error:
        warn_once("spawn", f"rerun: cannot spawn a viewer ({error}); running on")
        return
    if not viewer_reachable(url):
        warn_once("spawn", "rerun: the spawned viewer did not come up; running on without it")
        return
    sinks.append(rr.GrpcSink(url))
    opened.append("spawned viewer")


def check_rrd_file(path, footer=True) -> None:
    """After the stream is disconnected: `path` must end in rerun's end marker (without a
    `footer`, in a whole message). rerun only logs a write the disk refuses, so a full disk
    would leave a file cut mid-message that no reader opens; it is cut back to its last
    whole message (a readable recording, without the footer) and UsageError says so."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            return                               # a device or pipe: nothing to check
        with open(path, "rb") as file:
            data = file.read()
    except OSError:
        return
    position, messages = RRD_HEADER, 0
    while position + 16 <= len(data):
        kind, length = struct.unpack_from("<QQ", data, position)
        if position + 16 + length > len(data):
            break                                # cut in the middle of this message
        if kind == RRD_END:
            return                               # complete
        position, messages = position + 16 + length, messages + 1
    if not footer and messages and position == len(data):
        return                                   # complete: no end marker without a footer
    with open(path, "r+b") as file:
        file.truncate(position if messages else 0)
    raise UsageError(f"cannot write --rerun {path}: the disk refused part of it (full, or a "
                     f"file-size limit); the file is cut back to the {messages} whole messages "
                     "that fit and reads as a recording")
