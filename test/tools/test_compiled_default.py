"""The compiled path by default (issue 35): `arm-sim run --json` names the path it took;
numba installed, the compiled one; numba absent or broken, one line says so and the run goes
on in pure Python with the same numbers; ARM_SIM_COMPILED=0 chooses pure Python quietly."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ARM_SIM = str(Path(sys.executable).parent / "arm-sim")
RUN = [ARM_SIM, "run", "--scene", "release", "--duration", "0.05", "--json"]


def arm_sim_run(tmp_path, numba_imports=True, **env):
    """`arm-sim run --json` in a process of its own; numba_imports=False: its import fails
    as a broken install's does (a module of that name first on the path that raises)."""
    environment = {k: v for k, v in os.environ.items() if k != "ARM_SIM_COMPILED"} | env
    if not numba_imports:
        (tmp_path / "numba").mkdir()
        (tmp_path / "numba" / "__init__.py").write_text(
            'raise ImportError("libllvmlite.so: cannot open shared object file")\n')
        environment["PYTHONPATH"] = str(tmp_path)
    done = subprocess.run(RUN, env=environment, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout), done.stderr.splitlines()


def test_with_numba_the_run_takes_the_compiled_path(tmp_path):
    pytest.importorskip("numba")
    result, said = arm_sim_run(tmp_path)
    assert result["path"] == "compiled (numba)"
    assert not [line for line in said if "numba does not import" in line]


def test_without_numba_one_line_says_so_and_the_numbers_are_the_same(tmp_path):
    result, said = arm_sim_run(tmp_path, numba_imports=False)
    assert result["path"] == "python"
    assert [line for line in said if "numba" in line] == [
        "arm_sim_ros: numba does not import (ImportError: libllvmlite.so: cannot open shared "
        "object file): the pure-Python path, slower with the same numbers; `pip install "
        "numba==0.68.1` gives the compiled path (ARM_SIM_COMPILED=0 chooses pure Python "
        "without this line)"]
    chosen, quiet = arm_sim_run(tmp_path, ARM_SIM_COMPILED="0")
    assert not [line for line in quiet if "numba" in line]
    assert chosen == result             # the same run, digit for digit


def test_the_pin_is_the_one_the_line_names():
    setup = (Path(__file__).resolve().parents[2] / "setup.py").read_text()
    assert '"fast": ["numba==0.68.1"]' in setup
