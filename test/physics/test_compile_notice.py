"""A first compile says what it does, in one line before it starts, whether stderr is a
terminal, a file or a pipe; says it again at least every 10 s while it goes on; and no
time-left figure counts it (physics/compiled/cache.py, tools/progress.py)."""
import io

import pytest

from arm_sim_ros.physics.compiled import cache
from arm_sim_ros.tools import progress as progress_module
from arm_sim_ros.tools.progress import Progress
from tools.test_run_endings import Clock

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
    """A run whose first chunk waited 60 s on a compile, then did a quarter of its work in
    2 s: no time left right after the compile (its pace is not known), then about 4 s, not
    64."""
    clock, compiled = Clock(), [0.0]
    monkeypatch.setattr(progress_module, "compile_seconds", lambda: compiled[0])
    out = io.StringIO()
    bar = Progress(10.0, "arm-sim run release", stream=out, clock=clock)
    clock.now, compiled[0] = 62.0, 60.0
    bar.update(2.5)
    clock.now = 74.0
    bar.update(7.5)
    assert out.getvalue().splitlines() == [
        "arm-sim run release: 2.5 of 10 s (25.0 %), time left not known yet",
        "arm-sim run release: 7.5 of 10 s (75.0 %), about 6 s left"]


def test_the_first_compile_is_said_on_stderr_that_is_no_terminal(capsys, monkeypatch):
    """`arm-sim ... 2>log`: the notice is the log's first line (it was said only to a
    terminal, so a file or CI showed minutes of nothing)."""
    import logging
    from arm_sim_ros.tools import cli
    monkeypatch.setattr(cache, "COMPILES", cache.Compiles())
    # a node run earlier in this process left its log lines on stderr (node.main's
    # configure_logging): the command line's own stderr is what this asks about
    monkeypatch.setattr(logging.getLogger(), "handlers", [])
    assert cli.main(["scenes"]) == 0
    capsys.readouterr()
    cache.COMPILES.on_start(KERNEL)
    cache.COMPILES.on_end()
    err = capsys.readouterr().err
    assert err.startswith("arm-sim: compiling this scene's kernels once for this machine, about ")


def test_a_long_compile_says_so_at_least_every_10_s_and_nothing_counts_it(monkeypatch):
    """A progress line, then a 95 s compile (the main thread blocked in it), then the work:
    with the pulse ticking every 0.5 s on an injected clock, no two lines are more than 10 s
    apart, the notice comes first in the compile, and no line gives a time left from it."""
    clock, out = Clock(), io.StringIO()
    lines = progress_module.Lines(out, clock)
    under_way, compiled = [None], [0.0]
    monkeypatch.setattr(progress_module, "compile_seconds", lambda: compiled[0])
    monkeypatch.setattr(cache, "listeners", [lambda line: lines.say(f"arm-sim: {line}")])
    monkeypatch.setattr(cache, "COMPILES", cache.Compiles())
    pulse = cache.Pulse(lambda line: lines.say(f"arm-sim: {line}"), last_line=lambda: lines.last,
                        clock=clock, under_way=lambda: under_way[0])
    bar = Progress(100.0, "arm-sim run stick_slip", clock=clock, lines=lines)
    stamps = []

    def at(now, done=None):
        clock.now = now
        before = out.getvalue().count("\n")
        if done is not None:
            bar.update(done)
        pulse.tick()
        stamps.extend([now] * (out.getvalue().count("\n") - before))

    for tick in range(0, 20):                  # 10 s of work before the compile
        at(tick * 0.5, done=tick * 0.1)
    cache.COMPILES.on_start(KERNEL)            # the notice, at once
    stamps.append(clock.now)
    for tick in range(1, 191):                 # 95 s compiling: only the pulse runs
        under_way[0] = tick * 0.5
        at(9.5 + tick * 0.5)
    cache.COMPILES.on_end()
    under_way[0], compiled[0] = None, 95.0
    for tick in range(1, 61):                  # 30 s of work after it
        at(104.5 + tick * 0.5, done=2.0 + tick * 0.5)
    said = out.getvalue().splitlines()
    assert said[1].startswith("arm-sim: compiling this scene's kernels once for this machine")
    assert said[2] == "arm-sim: still compiling this scene's kernels, 8 s so far"
    assert max(b - a for a, b in zip(stamps, stamps[1:])) <= 10.0
    assert len(stamps) == len(said) and stamps[-1] - stamps[0] > 100
    after = [line for line in said if "stick_slip:" in line and stamps[said.index(line)] > 104.5]
    # the pace after the compile (2 s for 2 s of work) gives it; counting the compile would
    # have said about 40 min
    assert after[0] == "arm-sim run stick_slip: 4.5 of 100 s (4.5 %), about 96 s left"


def test_the_node_hears_a_long_compile_on_its_log(monkeypatch):
    """The node's pulse says it on the logger arm_sim_ros.compile, as the notice."""
    clock, logged, under_way = Clock(), [], [None]
    monkeypatch.setattr(cache.notice, "said", float("-inf"))
    pulse = cache.Pulse(logged.append, clock=clock, under_way=lambda: under_way[0])
    clock.now = 20.0
    assert pulse.tick() is None and logged == []        # nothing compiles: nothing said
    under_way[0] = 12.0
    assert pulse.tick() == "still compiling this scene's kernels, 12 s so far"
    clock.now = 25.0
    assert pulse.tick() is None
    clock.now = 29.0
    assert len(logged) == 1 and pulse.tick() and len(logged) == 2


def test_still_compiling_counts_the_whole_run_s_compiles(monkeypatch):
    """stick_slip compiles its modes one after another: the pulse read "9 s so far", then
    "1 s so far" at the next mode's start."""
    clock = iter([10.0, 14.0, 20.0, 23.0])
    monkeypatch.setattr(cache.time, "perf_counter", lambda: next(clock))
    compiles = cache.Compiles()
    compiles.on_start(KERNEL)          # 10.0
    compiles.on_end()                  # 14.0: the first mode, 4 s
    compiles.on_start(KERNEL)          # 20.0: the next mode
    assert compiles.under_way() == 7.0   # at 23.0: 4 + 3, not 3


def test_a_run_s_first_plain_line_comes_a_period_after_it_started():
    """The stream's last line may be long ago (its import): a run of 5 s still says nothing,
    as before (a one-line error test met a progress line at 2 s)."""
    clock, out = Clock(), io.StringIO()
    lines = progress_module.Lines(out, clock)
    clock.now = 100.0
    bar = Progress(100.0, "arm-sim run release", clock=clock, lines=lines)
    clock.now = 105.0
    bar.update(5.0)
    assert out.getvalue() == ""
    clock.now = 100.0 + progress_module.PLAIN_PERIOD
    bar.update(7.5)
    assert out.getvalue().startswith("arm-sim run release: 7.5 of 100 s")
