"""`arm-sim inspect --source SCENE`: the module a scene compiles to, as the compiled path
writes it to the kernel cache, printed without compiling anything."""
import os

import pytest

from arm_sim_ros.physics.compiled import build
from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.tools import cli


def printed(capsys, *argv) -> str:
    assert cli.main(["inspect", *argv]) == 0
    return capsys.readouterr().out


@pytest.mark.parametrize("scene", ["release", "stick_slip", "geared_arm"])
def test_the_source_is_the_module_the_compiled_path_loads(scene, capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("ARM_SIM_CACHE", str(tmp_path))
    out = printed(capsys, "--source", scene)
    name_line, about, text = out.split("\n", 2)
    monkeypatch.setenv("ARM_SIM_COMPILED", "0")
    sim = Simulator(load_scene(scene))
    assert text == build.module_source(sim.dynamics, sim._step)[0]
    assert name_line == (f"# {build.module_name(text)}.py: not compiled yet; its first compiled "
                         f"run writes it into the kernel cache {tmp_path}")
    assert about.startswith(f"# scene {scene}: {sim.scene.method}, effects gravity")
    compile(text, name_line, "exec")                   # Python, whole
    assert "def run_books(" in text and "@njit(cache=True)" in text
    assert os.listdir(tmp_path) == []                  # nothing compiled, nothing written


def test_the_header_says_whether_the_cache_holds_the_module(capsys, monkeypatch, tmp_path):
    """It named a file in the cache that no run had written ("... .py in ~/.cache/...")."""
    monkeypatch.setenv("ARM_SIM_CACHE", str(tmp_path))
    name_line, _, text = printed(capsys, "--source", "release").split("\n", 2)
    assert "not compiled yet" in name_line
    (tmp_path / f"{build.module_name(text)}.py").write_text(text)     # as build.load writes it
    assert printed(capsys, "--source", "release").split("\n", 1)[0] == (
        f"# {build.module_name(text)}.py: in the kernel cache {tmp_path}")


def test_the_source_says_which_path_runs_it(capsys, monkeypatch):
    monkeypatch.setenv("ARM_SIM_COMPILED", "0")
    assert "runs on Python's path" in printed(capsys, "--source", "release").split("\n")[1]
    assert "runs on Python's path" in printed(capsys, "--source", "servo_hold").split("\n")[1]


def test_inspect_wants_a_recording_or_a_scene_and_says_so(capsys, tmp_path):
    for argv, said in [([], "inspect needs a recording (REC.rrd), or --source SCENE"),
                       (["x.rrd", "--source", "release"], "not both"),
                       (["--source", "relase"], "did you mean 'release'"),
                       (["--source", str(tmp_path / "adaptive.yaml")], "an adaptive step")]:
        if argv and argv[-1].endswith("adaptive.yaml"):
            (tmp_path / "adaptive.yaml").write_text("integrator: dopri5\n", encoding="utf-8")
        assert cli.main(["inspect", *argv]) == 2
        assert said in capsys.readouterr().err


@pytest.mark.parametrize("command", [["inspect", "--source"], ["run", "--duration", "0.1",
                                                                  "--scene"]])
def test_a_scene_path_that_is_no_scene_file_says_what_it_is(capsys, tmp_path, command):
    """Issue 47: a directory "does not exist"; a file that is no scene (an unreadable one for
    anyone but root, /etc/shadow) had its first line echoed as an "unknown scene key"."""
    (tmp_path / "folder.yaml").mkdir()
    os.mkfifo(tmp_path / "pipe.yaml")
    (tmp_path / "shadow").write_text("root:$y$j9T$secret:20228:0:99999:7:::\n"
                                     "daemon:*:20228:0:99999:7:::\n", encoding="utf-8")
    (tmp_path / "metadata.yaml").write_text("rosbag2_bagfile_information:\n  version: 9\n",
                                            encoding="utf-8")
    cases = {"folder.yaml": "scene file {} is a directory, not a YAML file",
             "pipe.yaml": "scene file {} is not a regular file (a device or a pipe), not a YAML "
                          "file",
             "shadow": "{} is not a scene file: not one of its keys is a scene key",
             "metadata.yaml": "{} is not a scene file: not one of its keys is a scene key",
             "absent.yaml": "scene file {} does not exist"}
    for name, said in cases.items():
        path = str(tmp_path / name)
        assert cli.main([*command, path]) == 2
        out, err = capsys.readouterr()
        assert out == "" and err.startswith("arm-sim: error: " + said.format(path)), err
        assert err.count("\n") == 1 and "secret" not in err and "daemon" not in err
