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

The suite leaves the checkout as it found it: `git status` (ignored files too, each with its
size and time) is taken before the first test and compared after the last, by the process
that runs the suite (not its xdist workers); any difference fails the run (exit 1) with the
paths, whatever each test reported. Left out: what Python
and pip keep there (byte code, numba's cache beside it, the venvs, *.egg-info) and pytest's
own .pytest_cache. scripts/test runs the suite from a copy of the checkout (the files git
sees), so the checkout compared is that copy, where only the suite writes: what a person does
in the checkout meanwhile (scripts/run, a guide's example, an edit) is no part of the run.

No process of the suite compiles a kernel itself: numba keeps all a compile made for the
life of the process (about 40 MB a scene structure, where a kernel loaded from the cache
costs about 2 MB), which grew each xdist worker to gigabytes. build.load has a child process
compile a kernel first met (physics/compiled/apart.py); a kernel function compiled in a
process of the suite all the same fails the run, named. Each process's peak memory is said
at the end. Hypothesis keeps its files in a temporary directory, not in .hypothesis/
of the working directory, and draws the same examples every run (derandomize, no database):
the suite is deterministic.
"""
import os
import resource
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from hypothesis import configuration, settings

CHECKOUT = Path(__file__).resolve().parents[1]
BEFORE, CHANGED = pytest.StashKey[dict](), pytest.StashKey[list]()
PROCESSES = pytest.StashKey[dict]()      # {process: (peak MB, kernel functions compiled there)}
_session = []
_hypothesis_home = Path(tempfile.mkdtemp(prefix="arm_sim_hypothesis_"))
configuration.set_hypothesis_home_dir(_hypothesis_home)
settings.register_profile("arm_sim", derandomize=True, database=None)
settings.load_profile("arm_sim")


def checkout_state(root: Path = CHECKOUT) -> dict | None:
    """{path: (git status, size, mtime)} of everything git sees in `root`, ignored files
    included, one by one; None where `root` is not the top of a git work tree."""
    try:
        top = subprocess.run(["git", "rev-parse", "--show-toplevel"], cwd=root,
                             capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    if Path(top).resolve() != root.resolve():
        return None
    venvs = {p.parent.name for p in root.glob("*/pyvenv.cfg")}
    leave_out = [f":(exclude){name}" for name in sorted(venvs | {".pytest_cache"})] + [
        ":(exclude,glob)**/__pycache__/**", ":(exclude,glob)**/*.egg-info/**"]
    listed = subprocess.run(["git", "status", "--porcelain=v1", "-z", "--ignored=traditional",
                             "--untracked-files=all", "--", ".", *leave_out], cwd=root,
                            capture_output=True, check=True).stdout.decode()
    state, records = {}, iter(listed.split("\0"))
    for record in records:
        if not record:
            continue
        status, path = record[:2], record[3:]
        if status[0] in "RC":
            next(records, None)              # the rename's source follows
        try:
            stat = os.lstat(root / path)
            state[path] = (status, stat.st_size, stat.st_mtime_ns)
        except OSError:
            state[path] = (status, None, None)
    kept = venvs | {".git", ".pytest_cache", "__pycache__"}
    for entry in root.iterdir():           # git lists no directory that holds no file
        if entry.is_dir() and entry.name not in kept and not entry.name.endswith(".egg-info"):
            state.setdefault(f"{entry.name}/", ("dir", None, None))
    return state


def changed_paths(before: dict, after: dict) -> list:
    """`new PATH`, `removed PATH`, `changed PATH`: what differs between two states."""
    return [f"{'new' if p not in before else 'removed' if p not in after else 'changed'} {p}"
            for p in sorted(set(before) | set(after)) if before.get(p) != after.get(p)]


def compiled_here() -> list:
    """The kernel functions this process compiled itself (`module.function(signature)`),
    where build.load's kernels are loaded from the cache a child process wrote."""
    if "numba" not in sys.modules:
        return []
    from numba.core.registry import CPUDispatcher
    return sorted(f"{name}.{attribute}{signature}"
                  for name, module in list(sys.modules.items())
                  if name.startswith("arm_sim_kernel_")
                  for attribute, function in vars(module).items()
                  if isinstance(function, CPUDispatcher)
                  for signature in function.overloads
                  if not function.stats.cache_hits.get(signature))


def this_process() -> tuple:
    """(peak resident memory in MB, kernel functions compiled here)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024, compiled_here()


def pytest_sessionstart(session):
    _session[:] = [session]
    session.config.stash[CHANGED] = []
    session.config.stash[PROCESSES] = {}
    # the run's own process says it; an xdist worker is a part of the run
    worker = hasattr(session.config, "workerinput")
    session.config.stash[BEFORE] = None if worker else checkout_state()


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error):
    """An xdist worker's account (its pytest_sessionfinish), heard by the run's process."""
    if "arm_sim" in getattr(node, "workeroutput", {}):
        node.config.stash[PROCESSES][node.gateway.id] = node.workeroutput["arm_sim"]


def pytest_sessionfinish(session):
    shutil.rmtree(_hypothesis_home, ignore_errors=True)
    config = session.config
    if hasattr(config, "workerinput"):
        config.workeroutput["arm_sim"] = this_process()
        return
    processes = config.stash[PROCESSES]
    processes["main"] = this_process()
    before = config.stash.get(BEFORE, None)
    after = checkout_state() if before is not None else None
    if after is not None and (changed := changed_paths(before, after)):
        config.stash[CHANGED] = changed
    if config.stash[CHANGED] or any(compiled for _, compiled in processes.values()):
        if session.exitstatus in (pytest.ExitCode.OK, pytest.ExitCode.NO_TESTS_COLLECTED):
            session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_terminal_summary(terminalreporter, config):
    if changed := config.stash.get(CHANGED, []):
        copy = Path(os.environ.get("ARM_SIM_SUITE_COPY") or "/").resolve() == CHECKOUT
        terminalreporter.section("the checkout changed", red=True)
        terminalreporter.line(
            "The suite must leave the checkout as it found it; these changed while it ran "
            + ("(in the copy scripts/test runs it from: a test wrote there):" if copy else
               "(a test wrote there, or you did meanwhile):"))
        for line in changed:
            terminalreporter.line(f"  {line}")
    processes = config.stash.get(PROCESSES, {})
    if compiled := sorted({f for _, found in processes.values() for f in found}):
        terminalreporter.section("kernels compiled in the suite's processes", red=True)
        terminalreporter.line("numba keeps what a compile made for the life of the process "
                              "(tens of MB a scene); these were not loaded from the cache a "
                              "child process wrote (physics/compiled/apart.py):")
        for line in compiled:
            terminalreporter.line(f"  {line}")
    if processes:
        terminalreporter.write_line("peak memory: " + ", ".join(
            f"{name} {peak} MB" for name, (peak, _) in sorted(processes.items())))


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    if not _session or os.environ.get("ARM_SIM_KEEP_TEARDOWN") == "1":
        return
    if isinstance(sys.exc_info()[1], pytest.UsageError):
        return
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(int(_session[0].exitstatus))
