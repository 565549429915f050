"""The console script `arm_sim_node`: SIGINT and SIGTERM handled from its first instant.

Importing the node (numpy, the physics, yaml) takes one or two seconds before main.main runs;
a signal met there was a KeyboardInterrupt traceback, and one met later, while the node
started, ended it with no line and no recording. This module imports nothing heavy: it
installs the stop (stop.Stop) first, then imports and runs the node. A signal while the node
starts lets the start finish, so that a recording asked for is opened and closed whole,
and the node stops before its first step, saying so (main.run_dds); a second signal does
not wait.
"""
from __future__ import annotations

import sys

from .stop import Stop, stopped_while_starting


def main(argv=None) -> int:
    stop = Stop()
    stop.starting = True
    stop.install()
    try:
        from .main import main as node_main
    except KeyboardInterrupt:
        print(stopped_while_starting(stop, "no recording was written"), file=sys.stderr)
        return 0
    return node_main(argv, stop)


if __name__ == "__main__":
    sys.exit(main())
