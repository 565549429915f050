"""scripts/run and scripts/test: this checkout's node in any shell, set-up once, then offline.

The scripts are run as a user runs them. A fake venv (a python that logs `-m pip` calls and
otherwise hands over to the real one) shows when pip would run without touching the network;
a decoy arm_sim_node first on PATH shows that nothing from elsewhere is ever executed.
"""
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
REAL_BIN = Path(sys.executable).parent
DOMAIN_ID = "201"   # unique in the suite: the node below runs on the dds transport


def fake_venv(directory: Path) -> Path:
    """bin/python: `-m pip ...` is logged to pip.log and succeeds; anything else runs the real
    python. bin/arm_sim_node is the real venv's node (this checkout, installed editable)."""
    bin_dir = directory / "bin"
    bin_dir.mkdir(parents=True)
    (bin_dir / "python").write_text(
        "#!/bin/sh\n"
        f'if [ "$1" = "-m" ] && [ "$2" = "pip" ]; then echo "$@" >> "{directory}/pip.log"; '
        "exit 0; fi\n"
        f'exec "{sys.executable}" "$@"\n')
    (bin_dir / "arm_sim_node").write_text(
        f'#!/bin/sh\nexec "{REAL_BIN / "arm_sim_node"}" "$@"\n')
    for name in ("python", "arm_sim_node"):
        (bin_dir / name).chmod(0o755)
    return directory


def decoy_path(directory: Path) -> str:
    """A PATH whose first entry holds an arm_sim_node that leaves a mark if it is ever run."""
    directory.mkdir()
    decoy = directory / "arm_sim_node"
    decoy.write_text(f'#!/bin/sh\ntouch "{directory}/DECOY_RAN"\nexit 127\n')
    decoy.chmod(0o755)
    return f"{directory}:{os.environ['PATH']}"


def pip_calls(venv: Path) -> list:
    log = venv / "pip.log"
    return log.read_text().splitlines() if log.exists() else []


def copy_of_checkout(tmp_path: Path) -> Path:
    """scripts/ and setup.py are all the scripts read from a checkout."""
    root = tmp_path / "checkout"
    shutil.copytree(ROOT / "scripts", root / "scripts")
    shutil.copy(ROOT / "setup.py", root / "setup.py")
    return root


def run(command, env, timeout=60):
    return subprocess.run(command, env=env, capture_output=True, text=True, timeout=timeout)


def node_env(venv: Path, **more) -> dict:
    env = dict(os.environ, ARM_SIM_VENV=str(venv), ROS_DOMAIN_ID=DOMAIN_ID,
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", **more)
    env.pop("PYTHONPATH", None)   # no rclpy can import: the venv's node on dds
    return env


def test_with_ros_sourced_and_a_decoy_on_path_run_starts_this_checkouts_node(tmp_path):
    checkout = copy_of_checkout(tmp_path)
    venv = fake_venv(tmp_path / "venv")
    env = node_env(venv, ROS_DISTRO="jazzy", PATH=decoy_path(tmp_path / "elsewhere"))
    recording = tmp_path / "run.rrd"
    done = run([str(checkout / "scripts/run"), "--duration", "0.3",
                "--ros-args", "-p", f"rerun_path:={recording}"], env)
    assert done.returncode == 0, done.stderr
    assert not (checkout / "runs").exists()        # a recording named by the user: theirs alone
    assert not (tmp_path / "elsewhere" / "DECOY_RAN").exists()
    named = [line for line in done.stderr.splitlines() if line.startswith("scripts/run:")]
    assert named == [f"scripts/run: node {venv}/bin/arm_sim_node (venv {venv}, this checkout "
                     "installed editable), transport dds"]
    assert "scene release started" in done.stderr
    assert recording.stat().st_size > 0


def test_run_can_be_run_again_and_again_each_run_a_recording_of_its_own(tmp_path):
    """The README's headline command, three times in one checkout: each writes a new
    runs/arm_sim_<date>_<time>.rrd (a second one in the same second gets _2) and names it."""
    checkout = copy_of_checkout(tmp_path)
    env = node_env(fake_venv(tmp_path / "venv"))
    env.pop("ROS_DISTRO", None)
    named = []
    for _ in range(3):
        done = run([str(checkout / "scripts/run"), "--duration", "0.05"], env)
        assert done.returncode == 0, done.stderr
        started = [line for line in done.stderr.splitlines() if "started" in line]
        assert len(started) == 1 and "; recording runs/arm_sim_" in started[0], done.stderr
        named.append(started[0].split("; recording ")[1])
    assert len(set(named)) == 3
    assert sorted(p.relative_to(checkout).as_posix() for p in (checkout / "runs").iterdir()) \
        == sorted(named)
    assert all(re.fullmatch(r"runs/arm_sim_\d{4}-\d\d-\d\d_\d\d-\d\d-\d\d(_\d+)?\.rrd", name)
               and (checkout / name).stat().st_size > 0 for name in named)


def test_a_colcon_overlay_of_this_checkout_runs_when_ros_is_sourced(tmp_path):
    """WS/src/arm_sim_ros with WS/install built from it: the overlay's node, never PATH's."""
    workspace = tmp_path / "ws"
    checkout = copy_of_checkout(workspace / "src")
    node = workspace / "install/arm_sim_ros/lib/arm_sim_ros/arm_sim_node"
    node.parent.mkdir(parents=True)
    node.write_text('#!/bin/sh\necho "overlay node: $*"\n')
    node.chmod(0o755)
    (workspace / "install/setup.bash").write_text("export ARM_SIM_OVERLAY_SOURCED=1\n")
    env = dict(os.environ, ROS_DISTRO="jazzy", PATH=decoy_path(tmp_path / "elsewhere"),
               ARM_SIM_VENV=str(tmp_path / "no-venv"))
    done = run([str(checkout / "scripts/run"), "--duration", "1"], env)
    assert done.returncode == 0, done.stderr
    assert done.stderr.startswith(f"scripts/run: node {node} (colcon overlay {workspace}/install)")
    assert done.stdout.startswith("overlay node: --transport ")
    assert done.stdout.rstrip().endswith("-- --duration 1")
    assert not (tmp_path / "elsewhere" / "DECOY_RAN").exists()
    assert not (tmp_path / "no-venv").exists()   # no venv made, nothing installed


def test_an_overlay_of_another_checkout_is_not_used(tmp_path):
    """An install/ beside a directory that is not this checkout's workspace does not count."""
    checkout = copy_of_checkout(tmp_path / "mine")
    other = tmp_path / "install/arm_sim_ros/lib/arm_sim_ros/arm_sim_node"   # tmp_path/install
    other.parent.mkdir(parents=True)
    other.write_text(f'#!/bin/sh\ntouch "{tmp_path}/OTHER_RAN"\n')
    other.chmod(0o755)
    venv = fake_venv(tmp_path / "venv")
    (venv / "bin/arm_sim_node").write_text('#!/bin/sh\necho "venv node: $*"\n')
    env = dict(os.environ, ROS_DISTRO="jazzy", ARM_SIM_VENV=str(venv))
    done = run([str(checkout / "scripts/run"), "--transport", "dds"], env)
    assert done.returncode == 0, done.stderr
    assert not (tmp_path / "OTHER_RAN").exists()
    assert f"scripts/run: node {venv}/bin/arm_sim_node" in done.stderr
    assert "transport dds" in done.stderr


def test_setup_runs_pip_once_and_again_only_when_setup_py_changes(tmp_path):
    checkout = copy_of_checkout(tmp_path)
    venv = fake_venv(tmp_path / "venv")
    env = dict(os.environ, ARM_SIM_VENV=str(venv))
    env.pop("ROS_DISTRO", None)

    def test_script():
        done = run([str(checkout / "scripts/test"), "--version"], env)
        assert done.returncode == 0, done.stderr
        return pip_calls(venv)

    assert test_script() == [f"-m pip install --disable-pip-version-check --progress-bar off "
                             f"--only-binary numba,llvmlite -e {checkout}[test,bench,fit,fast]"]
    assert len(test_script()) == 1                      # set up: no pip, no network
    (venv / "bin/arm_sim_node").write_text("#!/bin/sh\nexit 0\n")
    assert run([str(checkout / "scripts/run")], env).returncode == 0
    assert len(pip_calls(venv)) == 1                    # the full install serves run too
    with open(checkout / "setup.py", "a") as setup:
        setup.write("# a dependency changed\n")
    assert len(test_script()) == 2                      # setup.py changed: install again
    assert len(test_script()) == 2


def test_a_venv_installed_from_another_checkout_is_installed_again(tmp_path):
    """The stamp names the checkout: an editable install of another one would run its code."""
    venv = fake_venv(tmp_path / "venv")
    env = dict(os.environ, ARM_SIM_VENV=str(venv))
    first, second = copy_of_checkout(tmp_path / "a"), copy_of_checkout(tmp_path / "b")
    for checkout in (first, second, first):
        assert run([str(checkout / "scripts/test"), "--version"], env).returncode == 0
    assert [call.split()[-1] for call in pip_calls(venv)] == [
        f"{first}[test,bench,fit,fast]", f"{second}[test,bench,fit,fast]",
        f"{first}[test,bench,fit,fast]"]


def test_set_up_says_why_it_installs_and_shows_its_progress(tmp_path):
    """It said "setup.py is new to this venv" whatever was new, then ~53 s of nothing."""
    checkout = copy_of_checkout(tmp_path)
    venv = fake_venv(tmp_path / "venv")
    python = venv / "bin/python"          # pip as it talks: a line per package, then the install
    python.write_text(python.read_text().replace(
        'exit 0; fi', 'printf "Collecting numpy==2.4.6\\n  Using cached numpy.whl\\nCollecting '
        'scipy==1.17.1\\nInstalling collected packages: numpy, scipy\\n"; exit 0; fi'))
    (venv / "bin/arm_sim_node").write_text("#!/bin/sh\nexit 0\n")
    env = dict(os.environ, ARM_SIM_VENV=str(venv))
    env.pop("ROS_DISTRO", None)

    def said(script):
        done = run([str(checkout / "scripts" / script)] + (["--version"] if script == "test"
                                                          else []), env)
        assert done.returncode == 0, done.stderr
        return [line for line in done.stderr.splitlines() if line.startswith("scripts:")]

    first = said("run")
    assert first[0] == (f"scripts: installing {checkout} into {venv} (nothing of this checkout "
                        "is installed in it yet); about a minute on first set-up, one line per "
                        "package")
    assert first[1:] == ["scripts: pip: collecting numpy==2.4.6",
                         "scripts: pip: collecting scipy==1.17.1",
                         "scripts: pip: installing 2 packages (the longest step)",
                         "scripts: installed; later runs start at once, with no network"]
    assert said("test")[0].endswith(" (the extras test,bench,fit are new to this venv); about a "
                                    "minute on first set-up, one line per package")
    with open(checkout / "setup.py", "a") as setup:
        setup.write("# a dependency changed\n")
    assert "(setup.py changed since its last install)" in said("test")[0]
    assert said("test") == []                            # set up: nothing to say


@pytest.mark.parametrize("script, extras", [("run", ""), ("test", "test,bench,fit")])
def test_numba_without_a_wheel_leaves_the_pure_python_path_in_one_line(tmp_path, script,
                                                                      extras):
    """The extra `fast` (numba) is tried from wheels only; where none exists for the machine,
    the install goes on without it, says so once, and is not tried again on every run."""
    checkout = copy_of_checkout(tmp_path)
    venv = fake_venv(tmp_path / "venv")
    python = venv / "bin/python"          # pip refuses the extra `fast`: no numba wheel here
    python.write_text(python.read_text().replace(
        'echo "$@" >> ', 'case "$*" in *fast*) exit 1;; esac; echo "$@" >> '))
    (venv / "bin/arm_sim_node").write_text("#!/bin/sh\nexit 0\n")
    env = dict(os.environ, ARM_SIM_VENV=str(venv))
    env.pop("ROS_DISTRO", None)
    command = [str(checkout / "scripts" / script)] + (["--version"] if script == "test" else [])
    done = run(command, env)
    assert done.returncode == 0, done.stderr
    said = [line for line in done.stderr.splitlines() if line.startswith("scripts: numba")]
    assert said == ["scripts: numba (the compiled path) has no wheel for this machine: the "
                    "simulator runs its pure-Python path (slower, the same numbers)"]
    target = f"{checkout}[{extras}]" if extras else str(checkout)
    assert pip_calls(venv) == [f"-m pip install --disable-pip-version-check --progress-bar off "
                               f"-e {target}"]
    assert run(command, env).returncode == 0
    assert len(pip_calls(venv)) == 1                    # set up: not tried on every run


@pytest.mark.parametrize("script", ["run", "test"])
def test_a_failed_first_install_says_why_and_is_not_127(tmp_path, script):
    checkout = copy_of_checkout(tmp_path)
    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    (venv / "bin/python").write_text(   # pip fails (offline); anything else is the real one
        f'#!/bin/sh\n[ "$1" = "-m" ] && exit 1\nexec "{sys.executable}" "$@"\n')
    (venv / "bin/python").chmod(0o755)
    env = dict(os.environ, ARM_SIM_VENV=str(venv))
    env.pop("ROS_DISTRO", None)
    done = run([str(checkout / "scripts" / script)], env)
    assert done.returncode == 1
    assert "pip could not install" in done.stderr
    assert not list(venv.glob(".arm_sim_ros-installed*"))


def old_python(path: Path, version: str = "3.10") -> Path:
    """A python that says it is `version` and leaves a mark if asked to make a venv or pip."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f'#!/bin/sh\n[ "$1" = "-c" ] && {{ echo {version}; exit 0; }}\n'
                    f'touch "{path.parent}/USED_FOR_$2"\nexit 1\n')
    path.chmod(0o755)
    return path


@pytest.mark.parametrize("script", ["run", "test"])
def test_an_older_python3_is_refused_in_one_line_before_any_venv_or_pip(tmp_path, script):
    checkout = copy_of_checkout(tmp_path)
    python = old_python(tmp_path / "bin/python3")
    env = dict(os.environ, PATH=f"{python.parent}:{os.environ['PATH']}",
               ARM_SIM_VENV=str(tmp_path / "venv"))
    env.pop("ROS_DISTRO", None)
    env.pop("ARM_SIM_PYTHON", None)
    done = run([str(checkout / "scripts" / script)], env)
    assert done.returncode == 1
    assert done.stderr.splitlines() == [
        "scripts: error: python3 is Python 3.10; arm_sim_ros needs 3.11 or newer (its pinned "
        "numpy and scipy do): install Python 3.11 or newer and run again with "
        "ARM_SIM_PYTHON=python3.11"]
    assert not (tmp_path / "venv").exists() and not list(python.parent.glob("USED_FOR_*"))


def test_arm_sim_python_chooses_the_python_that_makes_the_venv(tmp_path):
    checkout = copy_of_checkout(tmp_path)
    old_python(tmp_path / "bin/python3")
    env = dict(os.environ, PATH=f"{tmp_path / 'bin'}:{os.environ['PATH']}",
               ARM_SIM_VENV=str(tmp_path / "venv"), ARM_SIM_PYTHON=str(fake_python(tmp_path)))
    env.pop("ROS_DISTRO", None)
    done = run([str(checkout / "scripts/test"), "--version"], env)
    assert f"creating the venv {tmp_path / 'venv'} with {env['ARM_SIM_PYTHON']}" in done.stderr
    assert (tmp_path / "made-venv").read_text().split() == ["-m", "venv", str(tmp_path / "venv")]


def fake_python(tmp_path: Path) -> Path:
    """A current python whose `-m venv DIR` makes DIR a fake venv (fake_venv) and notes it."""
    path = tmp_path / "good/python"
    path.parent.mkdir()
    path.write_text(
        "#!/bin/sh\n"
        f'if [ "$1" = "-m" ] && [ "$2" = "venv" ]; then echo "$@" > "{tmp_path}/made-venv"; '
        f'exec "{sys.executable}" -c "import sys; sys.path.insert(0, \'{Path(__file__).parent}\'); '
        'from test_scripts import fake_venv; from pathlib import Path; '
        'fake_venv(Path(sys.argv[1]))" "$3"; fi\n'
        f'exec "{sys.executable}" "$@"\n')
    path.chmod(0o755)
    return path


def test_a_venv_of_an_older_python_is_refused_in_one_line_before_pip(tmp_path):
    checkout = copy_of_checkout(tmp_path)
    venv = tmp_path / "venv"
    old_python(venv / "bin/python")
    env = dict(os.environ, ARM_SIM_VENV=str(venv))
    env.pop("ROS_DISTRO", None)
    done = run([str(checkout / "scripts/run")], env)
    assert done.returncode == 1
    assert done.stderr.splitlines() == [
        f"scripts: error: the venv {venv} is Python 3.10; arm_sim_ros needs 3.11 or newer (its "
        "pinned numpy and scipy do): remove it and run again with ARM_SIM_PYTHON=python3.11 "
        "(or newer)"]
    assert not list(venv.glob("bin/USED_FOR_*"))


def test_the_python_requirement_is_said_once_and_every_pinned_dependency_meets_it():
    """setup.py's python_requires is what the README and package.xml say, and no pinned
    dependency installed here asks for a newer Python (numpy 2.4 and scipy 1.17 need 3.11)."""
    from importlib import metadata
    from packaging.requirements import Requirement
    from packaging.specifiers import SpecifierSet

    need = re.search(r'python_requires=">=([\d.]+)"', (ROOT / "setup.py").read_text())[1]
    assert f"Python {need} or newer" in (ROOT / "README.md").read_text()
    assert (f'<exec_depend version_gte="{need}">python3</exec_depend>'
            in (ROOT / "package.xml").read_text())
    major, minor = map(int, need.split("."))
    checked, older = {}, f"{major}.{minor - 1}.0"     # and none lower would be true
    for line in metadata.requires("arm_sim_ros"):
        requirement = Requirement(line)
        try:
            installed = metadata.distribution(requirement.name)
        except metadata.PackageNotFoundError:   # an extra not installed here (fast)
            continue
        if installed.version in requirement.specifier:
            floor = SpecifierSet(installed.metadata.get("Requires-Python") or "")
            checked[requirement.name] = (floor.contains(f"{need}.0"), floor.contains(older))
    assert checked["numpy"] == checked["scipy"] == (True, False)
    assert [name for name, (ok, _) in checked.items() if not ok] == []
