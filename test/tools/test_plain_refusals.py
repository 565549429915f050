"""Bad input is refused in one line, in the physics' words: duplicate scene keys, integers of
any length in a scene file, a `-p` or a parameter file, derived quantities that overflow
(refused when the scene is read, not in the step planner), and faults that name the arm,
not Python's "math domain error". Numbers rcl reads as doubles are doubles here too."""
import math

import pytest

from arm_sim_ros.node import main as node_main
from arm_sim_ros.node.params.parameters import resolve_parameters
from arm_sim_ros.node.params.values import ParameterRefused
from arm_sim_ros.node.params.ros_args import rcl_scalar
from arm_sim_ros.physics.model import arithmetic_fault
from arm_sim_ros.physics.scene import SceneError, load_scene
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.tools import cli

HUGE = "9" * 5000


def one_line_exit_2(capsys, run):
    code = run()
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert len(err) < 1000
    return err


@pytest.mark.parametrize("text, says", [
    ("name: twice\ndamping: 0.5\ndamping: 5.0\n", "'damping' is given twice"),
    ("name: nested\nfriction:\n  coulomb: [0.1, 0.1]\n  coulomb: [1, 1]\n", "given twice"),
    (f"name: big\ndamping: {HUGE}\n", "5000 digits"),
    (f"name: big\nlink_lengths: [1.0, -{HUGE}]\n", "5000 digits"),
], ids=["repeated", "repeated-nested", "integer", "negative-integer-in-a-list"])
def test_a_scene_file_with_a_repeated_key_or_an_endless_integer_is_one_line(
        tmp_path, capsys, text, says):
    path = tmp_path / "scene.yaml"
    path.write_text(text)
    err = one_line_exit_2(capsys, lambda: cli.main(["run", "--scene", str(path)]))
    assert says in err


def test_an_endless_integer_on_the_command_line_or_in_a_parameter_file_is_one_line(
        tmp_path, capsys):
    params = tmp_path / "params.yaml"
    params.write_text(f"arm_sim:\n  ros__parameters:\n    damping: {HUGE}\n")
    for ros_args in (["-p", f"damping:={HUGE}"], ["--params-file", str(params)],
                     ["-p", f"publish_rate:=-{HUGE}"]):
        err = one_line_exit_2(capsys, lambda: node_main.main(
            ["--transport", "dds", "--ros-args", *ros_args]))
        assert "refused" in err


@pytest.mark.parametrize("override", [
    {"motors.torque_constant": [1e200, 1e200]}, {"motors.gear_ratio": [1e200, 1e200]},
    {"controller_model.link_lengths": [1e200, 1e200]},
    {"motors.inductance": [1e-320, 1e-320]}])
def test_derived_quantities_that_overflow_are_refused_when_the_scene_is_read(override):
    name, value = next(iter(override.items()))
    effect, key = name.split(".")
    base = load_scene("motor_windings_hold")
    with pytest.raises(SceneError) as refused:
        base.replace(**{effect: {**(getattr(base, effect) or {}), key: value}})
    assert "double precision" in str(refused.value) or "overflows" in str(refused.value)
    with pytest.raises(ParameterRefused) as at_start:    # the node refuses at start, too
        resolve_parameters({"scene": "motor_windings_hold", **override})
    assert at_start.value.name == name


def test_a_step_that_leaves_the_doubles_is_named_in_the_arms_words():
    for error in (ValueError("math domain error"), ZeroDivisionError("float division by zero"),
                  OverflowError("math range error")):
        text = arithmetic_fault(error)
        assert "math" not in text and "float" not in text
    sim = Simulator(load_scene("release").replace(initial_velocities=(5e153, -5e153)))
    sim.run(0.05)
    assert sim.fault and "math domain error" not in sim.fault


@pytest.mark.parametrize("text, value", [
    ("0x1p-1074", 5e-324), ("-0x1.8p-1070", -1.2e-322), ("2.2250738585072014e-308", 2.2250738585072014e-308),
    ("1e-300", 1e-300), ("0x1F", 31), ("5e-324", "5e-324"), ("1e-400", "1e-400"),
    ("1e400", "1e400"), (HUGE, HUGE)], ids=lambda v: str(v)[:20])
def test_rcl_reads_a_number_as_a_double_exactly_when_glibc_strtod_does(text, value):
    # strtod sets ERANGE for a result rounded to a subnormal or to zero, or beyond the
    # doubles; rcl then keeps the text
    assert rcl_scalar(text) == value and type(rcl_scalar(text)) is type(value)


def test_a_number_read_as_text_is_refused_saying_why(capsys):
    err = one_line_exit_2(capsys, lambda: node_main.main(
        ["--transport", "dds", "--ros-args", "-p", "damping:=5e-324"]))
    assert "ROS 2 reads" in err and "as text" in err
    assert math.isclose(resolve_parameters({"damping": rcl_scalar("0x1p-1074")}).values["damping"],
                        5e-324)


@pytest.mark.parametrize("sets, says", [
    (["sensors.position_noise=-1e-4,0"], "sensors.position_noise[0] = -0.0001 is impossible"),
    (["sensors.position_resolution=0,1e-3"], "position_resolution[0] = 0 is impossible"),
    (["step_size=0.001", "sensors.delay=0.0025"], "sensors.delay = 0.0025 s is 2.5 steps"),
    (["step_size=0.001", "sensors.rate=300"], "1/rate must be a whole number of steps"),
    (["step_size=0.001", "command_delay=0.0015"], "command_delay = 0.0015 s is 1.5 steps"),
], ids=["negative noise", "zero resolution", "delay", "rate", "command delay"])
def test_sensors_that_cannot_be_are_one_line_and_exit_2(capsys, sets, says):
    err = one_line_exit_2(capsys, lambda: cli.main(
        ["run", "--scene", "release", *[a for s in sets for a in ("--set", s)]]))
    assert says in err
