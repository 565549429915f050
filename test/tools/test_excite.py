"""Issue 39: `arm-sim excite` never said "wrote" over a run that is no recording to fit: the
simulator's fault, values its checks let through (NaN is not <= 0), a scene whose servos
ignore the torque, a joint that never moved, a seed numpy refuses."""
from __future__ import annotations

import pytest

from arm_sim_ros.tools import cli


def excite(capsys, path, *args):
    status = cli.main(["excite", str(path), "--duration", "2", *args])
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    return status, out, err.strip()


def test_a_run_that_faults_writes_no_bag_and_exits_1_saying_why(capsys, tmp_path):
    """--peak 1e8,1e8 faulted from t = 0.002 s; it wrote "final q = (-11111.7, 1043.0)"."""
    status, out, err = excite(capsys, tmp_path / "bag", "--peak", "1e8,1e8")
    assert status == 1 and out == "" and len(err.splitlines()) == 1
    assert "the simulation faulted, so no recording was written" in err
    assert not (tmp_path / "bag").exists()


@pytest.mark.parametrize("args, expected", [
    (["--peak", "nan,1"], "--peak nan,1: two positive, finite torques"),
    (["--peak", "inf,1"], "--peak inf,1: two positive, finite torques"),
    (["--peak", "0,1"], "--peak 0,1: two positive, finite torques"),
    (["--noise", "nan,0"], "--noise nan,0: two finite numbers >= 0"),
    (["--noise", "0,-1"], "--noise 0,-1: two finite numbers >= 0"),
    (["--seed", "-1"], "--seed -1: a whole number >= 0"),
    (["--scene", "servo_hold"], "its servos follow set-points on joint 1 (position), joint 2 "
                                "(position) and ignore the torque")])
def test_values_and_scenes_it_cannot_record_with_are_one_line(capsys, tmp_path, args, expected):
    status, out, err = excite(capsys, tmp_path / "bag", *args)
    assert status == 2 and out == "" and expected in err and len(err.splitlines()) == 1
    assert not (tmp_path / "bag").exists()


def test_an_effort_servo_scene_is_recorded(capsys, tmp_path):
    status, out, err = excite(capsys, tmp_path / "bag", "--scene", "servo_hold", "--set",
                              "servo.interface=effort,effort")
    assert status == 0 and out.startswith("wrote"), err


def test_a_joint_that_never_moved_is_said_and_exits_1(capsys, tmp_path):
    """Static friction above the peak holds both joints: the bag is a still arm (noise on
    top), which a fit learns nothing from."""
    status, out, err = excite(capsys, tmp_path / "bag", "--set", "friction.coulomb=50,50",
                              "--noise", "1e-4,1e-3")
    assert status == 1 and out.startswith("wrote")
    assert "shoulder_joint and elbow_joint never moved" in err


@pytest.mark.parametrize("args", [
    ["--set", "sensors.delay=5", "--duration", "1"],    # read 5 s late: the readout is still
    ["--set", "sensors.position_resolution=100,100", "--set", "sensors.velocity=differences"],
    ["--noise", "1e3,1e3"]])                            # the motion drowned in the noise added
def test_readings_that_show_none_of_the_motion_exit_1(capsys, tmp_path, args):
    """Issue 47: `--set sensors.delay=5 --duration 1` recorded a still readout of a moving
    arm and exited 0. What is judged is what was recorded, as a fit reads it, not the truth."""
    status, out, err = excite(capsys, tmp_path / "bag", *args)
    assert status == 1 and out.startswith("wrote") and len(err.splitlines()) == 1
    assert ("the readings of shoulder_joint and elbow_joint in " + str(tmp_path / "bag")
            + " show no motion beyond their noise") in err
