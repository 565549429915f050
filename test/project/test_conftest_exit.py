"""test/conftest.py: its early exit keeps pytest's final exit status (and only skips the
teardown); the suite leaves the checkout as it found it, and what a person does in the
checkout meanwhile is not the suite's (scripts/test runs it from a copy); no process of the
suite compiles a kernel itself.

Each case runs a throwaway suite with a copy of the conftest in a fresh interpreter.
"""
import itertools
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from project.test_scripts import fake_venv

CONFTEST = Path(__file__).parents[1] / "conftest.py"
ROOT = Path(__file__).resolve().parents[2]
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


def throwaway_checkout(tmp_path, tests: str) -> Path:
    """A git work tree with a tracked file, an ignored runs/ holding a recording, the
    conftest, scripts/test and what it reads (scripts/venv.bash, setup.py), and test_x.py:
    `tests` after `ROOT`, the checkout the test file is in (Path(__file__))."""
    checkout = tmp_path / "checkout"
    (checkout / "test").mkdir(parents=True)
    (checkout / "runs").mkdir()
    (checkout / "runs/kept.rrd").write_text("the user's")
    (checkout / "tracked.txt").write_text("x")
    (checkout / ".gitignore").write_text("/runs/\n__pycache__/\n.pytest_cache/\n")
    shutil.copytree(ROOT / "scripts", checkout / "scripts")
    shutil.copy(ROOT / "setup.py", checkout / "setup.py")
    shutil.copy(CONFTEST, checkout / "test/conftest.py")
    (checkout / "pytest.ini").write_text("[pytest]\n")
    (checkout / "test/test_x.py").write_text(
        f"from pathlib import Path\nROOT = Path(__file__).resolve().parents[1]\n{tests}")
    for command in (["init", "-q"], ["add", "."]):
        subprocess.run(["git", *command], cwd=checkout, check=True)
    return checkout


def suite_env(**more) -> dict:
    return {k: v for k, v in os.environ.items()
            if k not in ("PYTHONPATH", "ARM_SIM_SUITE_COPY")} | NO_PLUGINS | more


def changed_section(out: str) -> list:
    """The paths the section "the checkout changed" names."""
    lines = out.split("the checkout changed", 1)[1].splitlines()[2:]
    return [line.strip() for line in itertools.takewhile(lambda l: l.startswith("  "), lines)]


@pytest.mark.parametrize("case", WRITES)
def test_a_suite_that_changes_the_checkout_fails_and_names_what_changed(tmp_path, case):
    """The suite run in the checkout (pytest, not scripts/test) with a copy of the conftest:
    whatever a test reports, a change fails the run."""
    tests, expected, lines = WRITES[case]
    checkout = throwaway_checkout(tmp_path, tests)
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "test"], cwd=checkout, capture_output=True, text=True, timeout=120,
                          env=suite_env())
    assert done.returncode == expected, done.stdout + done.stderr
    assert "1 passed" in done.stdout
    if lines:
        assert changed_section(done.stdout)[:len(lines)] == lines, done.stdout
    else:
        assert "the checkout changed" not in done.stdout


# A test that waits until the person at the keyboard has written into the checkout
WAITS = """import time
SIGNALS = Path({signals!r})
def test_a():
    (SIGNALS / "started").write_text("")
    deadline = time.monotonic() + 60
    while not (SIGNALS / "go").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert (SIGNALS / "go").exists()
"""


def scripts_test(checkout: Path, tmp_path: Path) -> subprocess.Popen:
    """scripts/test of the throwaway checkout, on a venv that hands over to this python
    (test_scripts.fake_venv: its pip only logs), its temporary files in tmp_path/tmp."""
    venv = fake_venv(tmp_path / "venv")
    (tmp_path / "tmp").mkdir()
    return subprocess.Popen([str(checkout / "scripts/test"), "-q", "-p", "no:cacheprovider",
                             "test"], env=suite_env(ARM_SIM_VENV=str(venv),
                                                    TMPDIR=str(tmp_path / "tmp")),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_what_a_person_does_in_the_checkout_meanwhile_is_not_the_suites(tmp_path):
    """scripts/run, the guides' examples or an edit during scripts/test: the suite runs from
    a copy, so the run stays green, and what the person wrote stays."""
    signals = tmp_path / "signals"
    signals.mkdir()
    checkout = throwaway_checkout(tmp_path, WAITS.format(signals=str(signals)))
    suite = scripts_test(checkout, tmp_path)
    deadline = time.monotonic() + 60
    while not (signals / "started").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    (checkout / "runs/arm_sim_2026-11-29_10-00-00.rrd").write_text("scripts/run's")
    (checkout / "run.csv").write_text("a guide's example")
    (checkout / "tracked.txt").write_text("an edit")
    (signals / "go").write_text("")
    out, err = suite.communicate(timeout=120)
    assert suite.returncode == 0, out + err
    assert "1 passed" in out and "the checkout changed" not in out
    assert (checkout / "runs/arm_sim_2026-11-29_10-00-00.rrd").read_text() == "scripts/run's"
    assert not list((tmp_path / "tmp").glob("arm_sim_suite.*"))     # the copy is gone


SUITE_WRITES = {
    "a recording": ("def test_a():\n    (ROOT / 'runs').mkdir()\n"
                    "    (ROOT / 'runs/written.rrd').write_text('the suite wrote')\n",
                    ["new runs/", "new runs/written.rrd"]),
    "a tracked file": ("def test_a(): (ROOT / 'tracked.txt').write_text('the suite wrote')\n",
                       ["changed tracked.txt"]),
}


@pytest.mark.parametrize("case", SUITE_WRITES)
def test_a_test_that_writes_into_the_checkout_fails_scripts_test_all_the_same(tmp_path, case):
    tests, lines = SUITE_WRITES[case]
    checkout = throwaway_checkout(tmp_path, tests)
    suite = scripts_test(checkout, tmp_path)
    out, err = suite.communicate(timeout=120)
    assert suite.returncode == 1, out + err
    assert "1 passed" in out
    assert changed_section(out) == lines, out
    assert "in the copy scripts/test runs it from: a test wrote there" in out
    assert (checkout / "tracked.txt").read_text() == "x"         # the checkout: untouched
    assert not (checkout / "runs/written.rrd").exists()


# --- no process of the suite compiles a kernel itself ---------------------------------------

COMPILES = """import sys
from arm_sim_ros.physics.compiled import build
def test_a(tmp_path, monkeypatch):
    monkeypatch.setenv("ARM_SIM_CACHE", str(tmp_path))
    if {here}:
        monkeypatch.setattr(sys, "executable", "/nonexistent/python")   # no child can
    module = build.load("from numba import njit\\n@njit(cache=True)\\n"
                        "def quarter(x):\\n    return x + 0.25 + {here}\\n")
    assert module.quarter(1.0) == 1.25 + {here}
"""


@pytest.mark.parametrize("workers", [[], ["-p", "xdist", "-n", "1"]], ids=["in process", "xdist"])
@pytest.mark.parametrize("here", [False, True], ids=["apart", "here"])
def test_a_kernel_compiled_in_a_process_of_the_suite_fails_the_run(tmp_path, here, workers):
    pytest.importorskip("numba")
    checkout = throwaway_checkout(tmp_path, COMPILES.format(here=here))
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           *workers, "test"], cwd=checkout, capture_output=True, text=True,
                          timeout=300, env=suite_env(PYTHONPATH=str(ROOT)))
    assert done.returncode == (1 if here else 0), done.stdout + done.stderr
    assert "1 passed" in done.stdout
    section = "kernels compiled in the suite's processes"
    assert (section in done.stdout) == here
    if here:
        named = done.stdout.split(section, 1)[1].splitlines()[2].strip()
        assert named.startswith("arm_sim_kernel_") and named.endswith(".quarter(float64,)")
    peaks = re.search(r"peak memory: (.*)", done.stdout)[1]
    assert re.fullmatch(r"gw0 \d+ MB, main \d+ MB" if workers else r"main \d+ MB", peaks)
