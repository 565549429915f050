"""Where a node's recording may go, checked before it is opened: a new .rrd file, checked
as `arm-sim run --rerun` checks it, and a viewer's address in one of the forms rerun takes
(any other text would be looked up as a host name, blocking a tick for seconds)."""
from __future__ import annotations

import os
from urllib.parse import urlsplit

from ...outputs import check_output
from ...usage import UsageError

SCHEMES = ("rerun+http", "rerun+https", "rerun")


def rerun_path_problem(path: str) -> str | None:
    """Why the node may not start a recording at `path` (a new .rrd in a writable
    directory; it never replaces a file), or None."""
    if not path:
        return None
    if "\x00" in path:
        return "a file name cannot hold a NUL character"
    if os.path.lexists(path) and not os.path.isdir(path):
        return f"{path} exists already; choose a new name (a recording is never replaced)"
    try:
        check_output(path, "rerun_path", force=True, suffixes=(".rrd",))
    except UsageError as error:
        return str(error)
    return None


def viewer_address_problem(address: str) -> str | None:
    """Why `address` is not a viewer's address (a port, host:port, or
    rerun+http://host:port/proxy), or None."""
    text = address.strip()
    if not text or text.isdigit() and 0 < int(text) < 65536:
        return None
    parts = urlsplit(text if "://" in text else f"rerun+http://{text}/proxy")
    try:
        port = parts.port
    except ValueError:
        port = None
    if parts.scheme in SCHEMES and parts.hostname and port and not parts.query:
        return None
    return ("rerun_connect must be a viewer's address: a port (9876), host:port "
            f"(127.0.0.1:9876) or rerun+http://host:port/proxy; got {address!r}")
