"""A kernel's first compile happens in a child process; this process loads the machine code
from the cache (physics/compiled/apart.py). numba keeps all a compile made for the life of
the process that made it (about 40 MB a scene structure, where a kernel loaded from the
cache costs about 2 MB): a suite worker or a node that met many scenes grew by gigabytes."""
import sys

import pytest

from arm_sim_ros.physics.compiled import cache

numba = pytest.importorskip("numba")
from arm_sim_ros.physics.compiled import build  # noqa: E402  (numba present)

# a caller and its callee, as a kernel module's run_books calls the scene's step
SOURCE = ("from numba import njit\n\n@njit(cache=True)\ndef half(x):\n    return 0.5 * x\n\n"
          "@njit(cache=True)\ndef twice(x):\n    return 4.0 * half(x) + {}\n")
FLOAT = (numba.float64,)


@pytest.fixture
def kernel(tmp_path, monkeypatch):
    """load(source): build.load into an empty cache, the compile notice heard (the lines
    are kernel.heard); the module leaves sys.modules after the test."""
    monkeypatch.setenv("ARM_SIM_CACHE", str(tmp_path))
    monkeypatch.setattr(cache, "COMPILES", cache.Compiles())
    heard = []
    monkeypatch.setattr(cache, "listeners", [heard.append])
    loaded = []

    def load(source):
        loaded.append(build.module_name(source))
        return build.load(source)
    load.heard = heard
    yield load
    for name in loaded:
        sys.modules.pop(name, None)


def compiled_here(dispatcher) -> list:
    """The signatures this process compiled itself (not loaded from the cache)."""
    return [sig for sig in dispatcher.overloads if not dispatcher.stats.cache_hits.get(sig)]


def test_a_first_compile_is_made_apart_and_loaded_here_from_the_cache(kernel):
    module = kernel(SOURCE.format("0.0"))
    assert module.twice(2.0) == 4.0
    assert module.twice.stats.cache_hits[FLOAT] == 1     # loaded, not compiled, here
    assert compiled_here(module.twice) == []
    assert module.half.overloads == {}                    # its callee: never typed here
    # the compile is announced and timed as numba's own (cache.py hears its event)
    assert len(kernel.heard) == 1 and cache.compile_seconds() > 0.0


def test_each_new_signature_is_compiled_apart(kernel):
    module = kernel(SOURCE.format("1.0"))
    assert module.twice(1.0) == 3.0
    assert module.twice(1) == 3.0                         # an int64 argument: a new one
    assert sorted(map(str, module.twice.stats.cache_hits)) == ["(float64,)", "(int64,)"]
    assert compiled_here(module.twice) == []


def test_where_no_child_can_compile_it_this_process_does(kernel, monkeypatch):
    monkeypatch.setattr(sys, "executable", "/nonexistent/python")
    module = kernel(SOURCE.format("2.0"))
    assert module.twice(1.0) == 4.0                       # the same function, compiled here
    assert compiled_here(module.twice) == [FLOAT]
    assert len(kernel.heard) == 1


def test_an_error_in_the_function_is_numbas_own(kernel):
    module = kernel("from numba import njit\n\n@njit(cache=True)\ndef broken(x):\n"
                    "    return x + 'a'\n")
    with pytest.raises(numba.core.errors.TypingError, match="add"):
        module.broken(1.0)


def test_an_entry_the_cache_lost_meanwhile_is_compiled_apart_again(kernel, monkeypatch):
    """Two processes writing one function's cache index at once: the later write may drop
    the other's entry (numba rewrites the index whole). A second child makes it again; where
    that fails as well, this process compiles it."""
    from arm_sim_ros.physics.compiled import apart
    real, children = apart.in_child, []

    def lost_once(module, function, args):
        children.append(function)
        return True if len(children) == 1 else real(module, function, args)
    monkeypatch.setattr(apart, "in_child", lost_once)
    module = kernel(SOURCE.format("3.0"))
    assert module.twice(1.0) == 5.0
    assert children == ["twice", "twice"] and compiled_here(module.twice) == []

    monkeypatch.setattr(apart, "in_child", lambda module, function, args: True)   # always lost
    assert module.twice(1) == 5.0
    assert compiled_here(module.twice) == [(numba.int64,)]


# A kernel module whose child never finishes its compile (it waits at import), for the stops
WAITING_CHILD = """import os, time
from numba import njit
if os.getpid() != {parent}:                     # the child (the parent runs this too)
    open({mark!r}, "w").write(str(os.getpid()))
    time.sleep(120)

@njit(cache=True)
def f(x):
    return x
"""
PARENT = """import os, sys
os.environ["ARM_SIM_CACHE"] = sys.argv[2]
from arm_sim_ros.physics.compiled import build
build.load(sys.argv[1].replace("{parent}", str(os.getpid()))).f(1.0)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
@pytest.mark.parametrize("stop", ["SIGINT", "SIGKILL"])
def test_a_child_ends_with_the_process_that_waits_for_it(tmp_path, stop):
    """Ctrl-C or SIGTERM (KeyboardInterrupt where the process has no handler of its own):
    subprocess.run ends the child. A process killed outright: the kernel ends it
    (PR_SET_PDEATHSIG). No compile goes on for nobody."""
    import os
    import signal
    import subprocess
    import time
    mark = tmp_path / "child"
    source = WAITING_CHILD.format(parent="{parent}", mark=str(mark))
    parent = subprocess.Popen([sys.executable, "-c", PARENT, source, str(tmp_path / "cache")],
                              stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not (mark.exists() and mark.read_text()) and time.monotonic() < deadline:
        time.sleep(0.05)
    child = int(mark.read_text())
    parent.send_signal(getattr(signal, stop))
    parent.communicate(timeout=30)
    deadline = time.monotonic() + 30
    while os.path.exists(f"/proc/{child}") and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not os.path.exists(f"/proc/{child}")
