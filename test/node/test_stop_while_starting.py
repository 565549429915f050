"""A signal in the node's first seconds, before its start line (issue 47, item 6): while its
modules were imported it was a KeyboardInterrupt traceback; while it started, exit 0 with
no line and no recording. Now the start finishes (a recording asked for is opened and
closed whole, holding the start), the node stops before its first step and says so.

Each node runs as `arm_sim_node` does: the console script's target named in setup.py, in a
process of its own, the signal raised by the process itself at a known moment (a hook), on
the dds transport on loopback with a domain of its own."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TARGET = re.search(r'"arm_sim_node = ([\w.]+):(\w+)"', (ROOT / "setup.py").read_text())
# The signal is raised when the process first imports `module` (its modules load), or
# when the dds node resolves its parameters (it starts, before its recorder and start line).
HOOKED = """
import os, signal, sys
MODULE, MOMENT = sys.argv[1], sys.argv[2]

def interrupt():
    os.kill(os.getpid(), signal.SIGINT)

class Hook:
    def find_spec(self, name, path=None, target=None):
        if name == MODULE:
            sys.meta_path.remove(self)
            interrupt()
        return None

if MOMENT == "importing":
    sys.meta_path.insert(0, Hook())
else:                         # the signal comes later: the modules may load first
    from arm_sim_ros.node.transports import dds
    resolve = dds.resolve_parameters

    def resolving(*args, **kwargs):
        interrupt()
        return resolve(*args, **kwargs)
    dds.resolve_parameters = resolving
module = __import__({module!r}, fromlist=["_"])
sys.exit(getattr(module, {function!r})(sys.argv[3:]))
""".format(module=TARGET[1], function=TARGET[2])


def node(tmp_path, moment, *parameters, domain):
    env = os.environ | {"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                        "ARM_SIM_COMPILED": "0"}
    done = subprocess.run([sys.executable, "-c", HOOKED, "arm_sim_ros.physics.scene", moment,
                           "--transport", "dds", "--quiet", "--duration", "3", "--ros-args",
                           *parameters], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=120)
    return done.returncode, done.stderr


@pytest.mark.parametrize("moment, domain", [("importing", 147), ("starting", 148)])
def test_a_signal_before_the_start_line_stops_the_node_saying_where_its_recording_is(
        tmp_path, moment, domain):
    import rerun as rr

    code, err = node(tmp_path, moment, "-p", "rerun_path:=early.rrd", domain=domain)
    assert code == 0 and "Traceback" not in err, err
    assert err.strip().splitlines()[-1] == ("arm_sim_node: stopped by SIGINT while it started, "
                                            "before its first step; its recording early.rrd "
                                            "holds its start")
    assert "started" in err                       # the start line: it named the recording
    chunks = list(rr.chunk.RrdReader(str(tmp_path / "early.rrd")).stream())
    assert chunks                                 # closed whole: readable


def test_a_node_stopped_while_it_started_without_a_recording_says_none_was_asked_for(tmp_path):
    code, err = node(tmp_path, "starting", domain=149)
    assert code == 0 and "Traceback" not in err, err
    assert err.strip().splitlines()[-1].endswith("before its first step; no recording was "
                                                 "asked for")
