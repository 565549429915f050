"""One Cyclone DDS per symbol scope: ROS 2's libddsc (rmw_cyclonedds, 0.10) and the cyclonedds
wheel's (11) export the same names, so a process must never let one bind to the other.

The node and the CLI keep them apart: the rclpy node maps only ROS's, the dds node and the
CLI only the wheel's, and a Cyclone another library made global (LD_PRELOAD, SROS2's
security plugins) is refused in one line instead of a crash. The ROS cases skip cleanly where
ROS 2 Jazzy with rmw_cyclonedds is not sourced. docs/guides/reliability.md, "At exit"."""
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from arm_sim_ros.node.wire import one_cyclone
from arm_sim_ros.node.wire.errors import DiscoveryError

BIN = Path(sys.executable).parent
DOMAIN_ID = "203"   # unique in the suite
WHEEL_LIBS = Path(one_cyclone.own_library_dirs()[0])


def env(**extra):
    return dict(os.environ, ROS_DOMAIN_ID=DOMAIN_ID, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                **extra)


def ros_libddsc() -> Path:
    """rmw_cyclonedds' Cyclone, where ROS 2 is sourced."""
    ament = pytest.importorskip("ament_index_python.packages")
    try:   # Cyclone is a plain CMake package: found beside rmw_cyclonedds_cpp, as Jazzy installs it
        library = Path(ament.get_package_prefix("rmw_cyclonedds_cpp")) / "lib" / "libddsc.so.0"
    except ament.PackageNotFoundError:
        pytest.skip("no Cyclone DDS of ROS 2 (rmw_cyclonedds) sourced")
    if not library.exists():
        pytest.skip(f"{library} not found")
    return library


def cyclones_mapped(command, seconds=4.0) -> set:
    """The Cyclone DDS C libraries a running process maps, by file name."""
    process = subprocess.Popen(command, env=env(), stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    try:
        time.sleep(seconds)
        maps = Path(f"/proc/{process.pid}/maps").read_text()
    finally:
        process.terminate()
        process.wait(timeout=30)
    return {Path(line.split()[-1]).name for line in maps.splitlines() if "libddsc" in line}


def test_neither_cyclone_is_in_the_global_scope_of_a_process_that_loaded_them():
    from arm_sim_ros.node.wire import messages  # noqa: F401  (loads the wheel's Cyclone)

    assert one_cyclone.global_cyclone() is None


def test_another_cyclone_in_the_global_scope_is_refused_in_one_line():
    with pytest.raises(DiscoveryError) as refused:
        one_cyclone.refuse_foreign_cyclone(lambda: "/opt/ros/jazzy/lib/libddsc.so.0.10.7")
    text = str(refused.value)
    assert "\n" not in text and "/opt/ros/jazzy/lib/libddsc.so.0.10.7" in text


def test_the_wheels_own_cyclone_in_the_global_scope_is_not_another():
    own = next(WHEEL_LIBS.glob("libddsc*"))
    one_cyclone.refuse_foreign_cyclone(lambda: str(own.resolve()))
    one_cyclone.refuse_foreign_cyclone(lambda: None)


def test_the_dds_node_runs_with_its_own_cyclone_preloaded():
    own = next(WHEEL_LIBS.glob("libddsc*"))
    done = subprocess.run([str(BIN / "arm_sim_node"), "--transport", "dds", "--duration", "0.1",
                           "--quiet"], env=env(LD_PRELOAD=str(own)), capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("command", [
    ["arm_sim_node", "--transport", "dds", "--duration", "0.1", "--quiet"],
    ["arm-sim", "send-torque", "--once", "--wait", "0.1", "0", "0"]])
def test_ros_cyclone_preloaded_is_refused_not_a_crash(command):
    library = ros_libddsc()
    done = subprocess.run([str(BIN / command[0]), *command[1:]],
                          env=env(LD_PRELOAD=str(library)), capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 2, (done.returncode, done.stderr)   # was SIGSEGV (-11)
    assert "another Cyclone DDS C library is loaded globally" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def test_the_rclpy_node_maps_only_ros_cyclone():
    pytest.importorskip("rclpy")
    mapped = cyclones_mapped([str(BIN / "arm_sim_node"), "--transport", "rclpy", "--quiet"])
    assert mapped and all(name.startswith("libddsc.so.0") for name in mapped), mapped


@pytest.mark.parametrize("command", [
    ["arm_sim_node", "--transport", "dds", "--quiet"],
    ["arm-sim", "send-torque", "--wait", "30", "0", "0"],
    ["arm-sim", "record", "--duration", "30", "{tmp}/bag"]])
def test_the_dds_node_and_the_cli_map_only_the_wheels_cyclone_with_ros_sourced(command, tmp_path):
    ros_libddsc()
    mapped = cyclones_mapped([str(BIN / command[0])] +
                             [part.format(tmp=tmp_path) for part in command[1:]])
    assert mapped == {p.name for p in WHEEL_LIBS.glob("libddsc*")}, mapped
