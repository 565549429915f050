"""A package a command needs and cannot import is one line saying what to install, never a
ModuleNotFoundError traceback (issue 47, item 6): cyclonedds on the colcon route (which
installs what rosdep supplies; rosdep has no key for it), dask.distributed for
`fit --scheduler` (the extra `fit`). Each case runs in a process of its own with the module
hidden (None in sys.modules: its import fails as a missing one does)."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from arm_sim_ros.node.wire.one_cyclone import CYCLONEDDS
from arm_sim_ros.tools.fit.command import FIT_EXTRA

SETUP = (Path(__file__).resolve().parents[2] / "setup.py").read_text(encoding="utf-8")
HIDDEN = ("import sys; sys.modules[{module!r}] = None; from {main} import main; "
          "sys.exit(main(sys.argv[1:]))")


def without(module: str, main: str, *argv, cwd=None):
    """(exit code, stdout, stderr) of `main`'s main(argv) with `module` hidden."""
    done = subprocess.run([sys.executable, "-c", HIDDEN.format(module=module, main=main), *argv],
                          capture_output=True, text=True, timeout=120, cwd=cwd)
    return done.returncode, done.stdout, done.stderr


@pytest.mark.parametrize("argv", [["send-torque", "1", "0", "--wait", "1"],
                                  ["record", "bag", "--duration", "1", "--wait", "1"]])
def test_a_wire_tool_without_cyclonedds_says_what_to_install(tmp_path, argv):
    code, out, err = without("cyclonedds", "arm_sim_ros.tools.cli", *argv, cwd=tmp_path)
    assert code == 2 and out == "" and "Traceback" not in err, err
    assert err == (f"arm-sim: error: arm-sim {argv[0]} runs on the dds transport, which needs "
                   "the cyclonedds package, not installed here (a colcon build does not install "
                   f"it): pip install {CYCLONEDDS}\n")
    assert not (tmp_path / "bag").exists()


def test_the_node_on_dds_without_cyclonedds_says_what_to_install():
    code, out, err = without("cyclonedds", "arm_sim_ros.node.main", "--transport", "dds",
                             "--duration", "0.1")
    assert code == 2 and "Traceback" not in err, err
    assert err.strip().splitlines()[-1] == (
        "arm_sim_node: error: the dds transport needs the cyclonedds package, not installed "
        f"here (a colcon build does not install it): pip install {CYCLONEDDS}")


def test_fit_with_a_scheduler_without_dask_distributed_names_the_extra(tmp_path):
    """Said before the recording is read: nothing is fitted that could not be sent."""
    code, out, err = without("distributed", "arm_sim_ros.tools.cli", "fit", "absent.csv",
                             "--free", "damping", "--scheduler", "tcp://127.0.0.1:8786",
                             cwd=tmp_path)
    assert code == 2 and out == "" and "Traceback" not in err and err.count("\n") == 1, err
    assert err.startswith("arm-sim: error: --scheduler needs dask.distributed, which does not "
                          "import here (")
    assert err.endswith(f"pip install 'arm_sim_ros[fit]' (the extra fit: {' '.join(FIT_EXTRA)})\n")


def test_the_install_lines_name_the_pins_of_setup_py():
    assert f'"{CYCLONEDDS}",' in SETUP
    extra = re.search(r'"fit": \[([^\]]*)\]', SETUP)[1]
    assert tuple(re.findall(r'"([^"]+)"', extra)) == FIT_EXTRA
