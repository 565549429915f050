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


# The throwaway suites load no installed plugin (xdist, hypothesis's, ...): the conftest needs
# none, and loading them all made each run's start about three times as long.
NO_PLUGINS = {"PYTEST_DISABLE_PLUGIN_AUTOLOAD": "1"}


def run_suite(tmp_path, tests, plugin, args):
    shutil.copy(CONFTEST, tmp_path / "conftest.py")
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    (tmp_path / "test_x.py").write_text(ATEXIT + tests)
    if plugin:
        (tmp_path / "late.py").write_text(plugin)
    env = {k: v for k, v in os.environ.items() if k != "ARM_SIM_KEEP_TEARDOWN"}
    env["PYTHONPATH"] = str(tmp_path)
    env |= NO_PLUGINS
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


# --- the suite leaves the checkout as it found it -----------------------------------------

WRITES = {
    "nothing": ("def test_a(tmp_path): (tmp_path / 'x').write_text('x')\n", 0, []),
    "a new file": ("def test_a(): (ROOT / 'written.txt').write_text('x')\n", 1,
                   ["new written.txt"]),
    "a tracked file": ("def test_a(): (ROOT / 'tracked.txt').write_text('y')\n", 1,
                       ["changed tracked.txt"]),
    "an ignored file": ("def test_a(): (ROOT / 'runs/kept.rrd').write_text('other')\n", 1,
                        ["changed runs/kept.rrd"]),
    "a move": ("def test_a(): (ROOT / 'runs/kept.rrd').rename(ROOT / 'aside.rrd')\n", 1,
               ["new aside.rrd", "removed runs/kept.rrd"]),
    "an empty directory": ("def test_a(): (ROOT / 'runs2').mkdir()\n", 1, ["new runs2/"]),
    "byte code": ("def test_a(): (ROOT / '__pycache__').mkdir()\n", 0, []),
}


@pytest.mark.parametrize("case", WRITES)
def test_a_suite_that_changes_the_checkout_fails_and_names_what_changed(tmp_path, case):
    """A throwaway checkout (a git work tree with a tracked file and an ignored runs/), its
    suite run with a copy of the conftest: whatever a test reports, a change fails the run."""
    tests, expected, lines = WRITES[case]
    checkout = tmp_path / "checkout"
    (checkout / "test").mkdir(parents=True)
    (checkout / "runs").mkdir()
    (checkout / "runs/kept.rrd").write_text("the user's")
    (checkout / "tracked.txt").write_text("x")
    (checkout / ".gitignore").write_text("/runs/\n__pycache__/\n")
    for command in (["init", "-q"], ["add", "tracked.txt", ".gitignore"]):
        subprocess.run(["git", *command], cwd=checkout, check=True)
    shutil.copy(CONFTEST, checkout / "test/conftest.py")
    (checkout / "pytest.ini").write_text("[pytest]\n")
    (checkout / "test/test_x.py").write_text(
        f"from pathlib import Path\nROOT = Path({str(checkout)!r})\n{tests}")
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "test"], cwd=checkout, capture_output=True, text=True, timeout=120,
                          env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
                          | NO_PLUGINS)
    assert done.returncode == expected, done.stdout + done.stderr
    assert "1 passed" in done.stdout
    if lines:
        section = done.stdout.split("the checkout changed", 1)[1].splitlines()
        assert [line.strip() for line in section[2:2 + len(lines)]] == lines, done.stdout
    else:
        assert "the checkout changed" not in done.stdout
