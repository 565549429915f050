"""conftest.py's early exit keeps pytest's final exit status (and only skips the teardown).

Each case runs a throwaway suite with a copy of the conftest in a fresh interpreter.
"""
import os
import pathlib
import shutil
import subprocess
import sys

import pytest

CONFTEST = pathlib.Path(__file__).parents[1] / "conftest.py"
ATEXIT = 'import atexit\natexit.register(lambda: print("ATEXIT-RAN"))\n'
LATE_EXIT = ("import pytest\n@pytest.hookimpl(trylast=True)\n"
             "def pytest_sessionfinish(session):\n    pytest.exit('late', returncode=4)\n")
LATE_STATUS = ("import pytest\n@pytest.hookimpl(trylast=True)\n"
               "def pytest_sessionfinish(session):\n    session.exitstatus = 3\n")

CASES = {
    "failing": ("def test_a(): assert 0\n", None, [], 1),
    "collection error": ("import no_such_module_here\n", None, [], 2),
    "clean": ("def test_a(): pass\n", None, [], 0),
    "no tests": ("X = 1\n", None, [], 5),
    "-x": ("def test_a(): assert 0\ndef test_b(): assert 0\n", None, ["-x"], 1),
    "late pytest.exit": ("def test_a(): pass\n", LATE_EXIT, ["-p", "late"], 4),
    "late exitstatus": ("def test_a(): pass\n", LATE_STATUS, ["-p", "late"], 3),
}


def run_suite(tmp_path, tests, plugin, args):
    shutil.copy(CONFTEST, tmp_path / "conftest.py")
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    (tmp_path / "test_x.py").write_text(ATEXIT + tests)
    if plugin:
        (tmp_path / "late.py").write_text(plugin)
    env = {k: v for k, v in os.environ.items() if k != "ARM_SIM_KEEP_TEARDOWN"}
    env["PYTHONPATH"] = str(tmp_path)
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("case", CASES)
def test_exit_status_is_pytests_final_one(tmp_path, case):
    tests, plugin, args, expected = CASES[case]
    done = run_suite(tmp_path, tests, plugin, args)
    assert done.returncode == expected, done.stdout + done.stderr
    if case != "collection error":  # the test module (and its atexit hook) never loads
        assert "ATEXIT-RAN" not in done.stdout  # left early: no interpreter teardown


def test_usage_error_still_printed(tmp_path):
    done = run_suite(tmp_path, "def test_a(): pass\n", None, ["-k", "and("])
    assert done.returncode == 4
    assert "Wrong expression passed to '-k'" in done.stderr
