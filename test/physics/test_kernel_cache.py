"""The kernel cache (physics/compiled/build.py, entries.py): a damaged entry is set aside and
compiled again, said in one line, on this run and never again; an unusable cache says once
why the run takes the pure-Python path. Each test has its own ARM_SIM_CACHE and a small
kernel module of its own (a scene's first compile takes seconds: the hunt in
test/tools/test_extremes_hunt.py damages real scenes' entries)."""
import sys

import pytest

numba = pytest.importorskip("numba")     # the compiled path's cache

from arm_sim_ros.physics.compiled import build, entries  # noqa: E402


def kernel_source(tag: str) -> str:
    """A kernel module of two functions, one calling the other (a callee's entry too)."""
    return (f"from numba import njit\n\n# {tag}\n@njit(cache=True)\ndef twice(x):\n"
            "    return 2.0 * x\n\n@njit(cache=True)\ndef quadruple(x):\n"
            "    return twice(twice(x))\n")


def fresh(source: str):
    """The module as a later run loads it: new dispatchers, reading the cache's files."""
    sys.modules.pop(build.module_name(source), None)
    entries.SAID.clear()
    return build.load(source)


def damage(path, how: str, rng) -> None:
    data = path.read_bytes()
    path.write_bytes({"truncated": data[:len(data) // 3],
                      "garbage": bytes(rng.integers(0, 256, len(data), dtype="uint8")),
                      "flipped": data[:len(data) // 2] + bytes([data[len(data) // 2] ^ 0x5A])
                      + data[len(data) // 2 + 1:],
                      "not utf-8": b"\xff\xfe\x00\x80" + data}[how])


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("ARM_SIM_CACHE", str(tmp_path))
    return tmp_path


@pytest.mark.parametrize("kind", ["py", "nbi", "nbc"])
@pytest.mark.parametrize("how", ["truncated", "garbage", "flipped", "not utf-8"])
def test_a_damaged_entry_is_set_aside_and_compiled_again_in_one_line(cache, capsys, kind, how):
    import numpy as np
    source = kernel_source(f"{kind} {how}")
    assert fresh(source).quadruple(1.5) == 6.0           # compiled, written to the cache
    files = (list(cache.glob("arm_sim_kernel_*.py")) if kind == "py"
             else list((cache / "__pycache__").glob(f"*.{kind}")))
    assert files
    for path in files:
        damage(path, how, np.random.default_rng(len(path.name)))
    capsys.readouterr()
    assert fresh(source).quadruple(1.5) == 6.0           # the later run: the right answer
    lines = capsys.readouterr().err.splitlines()
    damaged = [line for line in lines if "damaged" in line]
    assert len(damaged) == 1 and "held a damaged entry" in damaged[0] and "set aside" in damaged[0]
    # the rest, if the compile again took over 10 s: the compile pulse of an earlier test's
    # command line or node in this process (cache.Pulse), saying it goes on
    assert all("still compiling this scene's kernels" in line for line in lines
               if line not in damaged)
    assert list(cache.rglob("*.damaged"))
    assert fresh(source).quadruple(1.5) == 6.0           # and the one after: rebuilt, quiet
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("where", ["a file", "under a file", "/proc"])
def test_an_unusable_cache_says_once_why_the_run_takes_the_slow_path(tmp_path, monkeypatch,
                                                                    capsys, where):
    (tmp_path / "file").write_text("")
    path = {"a file": tmp_path / "file", "under a file": tmp_path / "file" / "cache",
            "/proc": "/proc/arm_sim_ros_cache"}[where]
    monkeypatch.setenv("ARM_SIM_CACHE", str(path))
    monkeypatch.delenv("ARM_SIM_COMPILED", raising=False)
    build.unusable.cache_clear()
    entries.say_once.cache_clear()
    assert not build.available() and not build.available()
    (line,) = capsys.readouterr().err.splitlines()
    assert f"the kernel cache {path} " in line and "the pure-Python path" in line
    assert "ARM_SIM_CACHE" in line
