"""Suite-wide: leave the process without the interpreter's teardown.

Seen twice in 2026-11 (once in CI, once with ROS sourced), after every test had passed and
been reported: "corrupted double-linked list" / "double free" while native libraries
(cyclonedds' C library with its threads, Rerun's sender, MuJoCo, rclpy's Cyclone) are
unloaded in an arbitrary order at exit, turning a green run into exit code 134. Not
reproduced in isolation (6 + 3 reruns of the suspects; with ROS sourced, 1100 runs of rclpy
beside cyclonedds and the suite with this teardown kept, under MALLOC_CHECK_=3 too: see
docs/guides/reliability.md, "At exit"). The results are final by then, so
the run exits with pytest's own status as soon as every plugin has finished: the session's
exitstatus as it stands at the last pytest_unconfigure, after every sessionfinish hook (a
later one may still change it, e.g. with pytest.exit(returncode=...)).

The exit skips atexit handlers as well: `coverage run -m pytest` would lose its data, so set
ARM_SIM_KEEP_TEARDOWN=1 for such runs. It also ends the calling process when pytest runs
in-process (pytest.main() from a script); set the variable there too. A usage error (e.g. a
bad -k expression, still propagating while pytest unconfigures) keeps the normal teardown:
pytest prints its message only afterwards.
"""
import os
import sys

import pytest

_session = []


def pytest_sessionstart(session):
    _session[:] = [session]


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    if not _session or os.environ.get("ARM_SIM_KEEP_TEARDOWN") == "1":
        return
    if isinstance(sys.exc_info()[1], pytest.UsageError):
        return
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(int(_session[0].exitstatus))
