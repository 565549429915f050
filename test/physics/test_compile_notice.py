"""Issue 35: a first compile says what it does, in one line before it starts, and no
progress estimate counts it (physics/compiled/cache.py, tools/progress.py)."""
import io

import pytest

from arm_sim_ros.physics.compiled import cache
from arm_sim_ros.tools import progress as progress_module
from arm_sim_ros.tools.progress import Progress

KERNEL = "arm_sim_kernel_0123456789abcdef0123"


@pytest.fixture
def heard(monkeypatch):
    """A fresh account of compiles, and the lines its listener hears."""
    lines = []
    monkeypatch.setattr(cache, "COMPILES", cache.Compiles())
    monkeypatch.setattr(cache, "listeners", [lines.append])
    return lines


def test_the_first_compile_of_a_kernel_module_is_announced_once(heard):
    compiles = cache.COMPILES
    compiles.on_start("numba.core.something")       # numba's own: not a scene's kernel
    compiles.on_end()
    assert heard == []
    for _ in range(3):
        compiles.on_start(KERNEL)
        compiles.on_start(KERNEL)                    # a callee compiled inside
        compiles.on_end()
        compiles.on_end()
    assert len(heard) == 1
    assert heard[0].startswith("compiling this scene's kernels once for this machine, about ")
    assert heard[0].endswith(" s (later runs load them from the cache)")


def test_the_estimate_is_the_compile_s_cpu_time_stretched_by_the_load(monkeypatch):
    monkeypatch.setattr(cache.os, "getloadavg", lambda: (8.0, 0.0, 0.0))
    monkeypatch.setattr(cache.os, "cpu_count", lambda: 2)
    assert cache.expected_seconds() == 4 * cache.FIRST_COMPILE_CPU["smooth"]
    monkeypatch.setattr(cache.os, "getloadavg", lambda: (0.5, 0.0, 0.0))
    assert cache.expected_seconds(True) == cache.FIRST_COMPILE_CPU["switching"]


def test_compile_time_is_counted_once_for_nested_compiles(heard, monkeypatch):
    clock = iter([10.0, 14.0, 100.0, 101.5])
    monkeypatch.setattr(cache.time, "perf_counter", lambda: next(clock))
    compiles = cache.COMPILES
    compiles.on_start(KERNEL)          # 10.0
    compiles.on_start(KERNEL)
    compiles.on_end()
    compiles.on_end()                  # 14.0
    compiles.on_start(KERNEL)          # 100.0
    compiles.on_end()                  # 101.5
    assert cache.compile_seconds() == 5.5


def test_a_kernel_compiled_for_the_first_time_is_heard_and_timed(heard, tmp_path,
                                                                monkeypatch):
    """A module build.load writes into an empty cache: numba compiles it at its first call
    (announced, timed), and a second process would load it (test: the same module again)."""
    numba = pytest.importorskip("numba")
    from arm_sim_ros.physics.compiled import build
    monkeypatch.setenv("ARM_SIM_CACHE", str(tmp_path))
    source = ("from numba import njit\n\n@njit(cache=True)\ndef twice(x):\n"
              "    return 2.0 * x + 0.0 * len(__name__)\n")
    module = build.load(source)
    assert module.__name__.startswith(cache.KERNEL_MODULES) and cache.compile_seconds() == 0.0
    assert module.twice(2.0) == 4.0
    assert len(heard) == 1 and cache.compile_seconds() > 0.0
    assert list((tmp_path / "__pycache__").glob(f"{module.__name__}.*.nbi"))
    assert numba.__version__


def test_the_time_left_leaves_the_compile_out(monkeypatch):
    """A run whose first chunk waited 60 s on a compile, then did half its work in 2 s:
    about 2 s left, not 62."""
    now, compiled = [0.0], [0.0]
    monkeypatch.setattr(progress_module, "compile_seconds", lambda: compiled[0])
    monkeypatch.setattr(progress_module, "PLAIN_PERIOD", 0.0)
    out = io.StringIO()
    bar = Progress(10.0, "arm-sim run release", stream=out, clock=lambda: now[0])
    now[0], compiled[0] = 62.0, 60.0
    bar.update(5.0)
    assert out.getvalue().strip() == "arm-sim run release: 5 of 10 s (50.0 %), about 2 s left"
