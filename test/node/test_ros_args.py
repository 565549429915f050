"""`--ros-args -p name:=value` and parameter files read on the dds transport exactly as
rcl's parameter parser reads them (rcl_yaml_param_parser get_value): the table below, and
where ROS 2 is sourced the same table through rclpy itself."""
import math

import pytest

from arm_sim_ros.node.params.ros_args import (load_params_file, node_identity, node_parameters,
                                              parse_ros_args, remap_name)
from arm_sim_ros.usage import UsageError

# -p value text -> what rcl makes of it
RCL_TABLE = [
    ("1e-3", 0.001), ("1E3", 1000.0), (".5", 0.5), ("1.", 1.0), ("-2.5e+4", -25000.0),
    ("100", 100), ("-7", -7), ("+5", 5), ("0x1F", 31), ("010", 8), ("0", 0),
    ("9223372036854775807", 9223372036854775807),
    ("9223372036854775808", 9.223372036854776e18),     # beyond int64: strtod reads it
    ("1e400", "1e400"),                                 # overflows strtod too: a string
    ("true", True), ("Yes", True), ("on", True), ("y", True), ("FALSE", False), ("off", False),
    ("tRuE", "tRuE"),                                   # not one of rcl's words
    (".inf", math.inf), ("-.Inf", -math.inf), ("inf", math.inf),
    ("'1.5'", "1.5"), ('"true"', "true"),               # quoted: always a string
    ("rk4", "rk4"), ("1_000", "1_000"), ("0x", "0x"),
    ("[1.0, 0.5]", [1.0, 0.5]), ("[1, 2]", [1, 2]), ("[a, b]", ["a", "b"]),
]


def parsed(text):
    (_, name, value), = parse_ros_args(["-p", f"x:={text}"])["assignments"]
    return value


@pytest.mark.parametrize("text, expected", RCL_TABLE)
def test_p_values_are_typed_as_rcl_types_them(text, expected):
    value = parsed(text)
    assert type(value) is type(expected) and value == expected


@pytest.mark.parametrize("text, message", [
    ("[1, 2.0]", "a list must hold one type"),
    ("[[1, 2], 3]", "cannot nest lists"),
    ("{a: 1}", "not a mapping"),
    ("", "has no value"),
    ("&a [1] ", None),
])
def test_values_rcl_refuses_are_one_line(text, message):
    if message is None:              # an anchor without an alias is plain YAML: accepted
        assert parsed(text) == [1]
        return
    with pytest.raises(UsageError, match=message) as error:
        parsed(text)
    assert "\n" not in str(error.value)


def test_a_400_digit_integer_is_a_string_not_an_overflow():
    assert parsed("1" * 400) == "1" * 400


def test_parameter_files_follow_the_same_rules(tmp_path):
    path = tmp_path / "params.yaml"
    path.write_text("arm_sim:\n  ros__parameters:\n    step_size: 1e-3\n    publish_rate: 100\n"
                    "    frame_id: '10'\n    damping: [0.5, 0.05]\n    rerun_spawn: no\n")
    assert load_params_file(str(path)) == {"step_size": 0.001, "publish_rate": 100,
                                           "frame_id": "10", "damping": [0.5, 0.05],
                                           "rerun_spawn": False}


@pytest.mark.parametrize("text, message", [
    ("arm_sim:\n  ros__parameters: [1, 2]\n", "ros__parameters must map names to values"),
    ("a: &x [1]\nb: *x\n", "aliases"),
    ("- 1\n- 2\n", "must map node names"),
])
def test_bad_parameter_files_are_one_line(tmp_path, text, message):
    path = tmp_path / "params.yaml"
    path.write_text(text)
    with pytest.raises(UsageError, match=message):
        load_params_file(str(path))


# -r rules -> (node name, namespace), as rcl_remap_node_name / rcl_remap_node_namespace read them
IDENTITY_TABLE = [
    ([], ("arm_sim", "/")),
    (["__node:=left"], ("left", "/")), (["__name:=left"], ("left", "/")),
    (["arm_sim:__node:=left"], ("left", "/")),          # a rule for this node
    (["other:__node:=left"], ("arm_sim", "/")),         # a rule for another node
    (["__node:=a", "__node:=b"], ("a", "/")),            # the first rule wins
    (["__ns:=/robot/left"], ("arm_sim", "/robot/left")), (["__ns:=/robot/"], ("arm_sim", "/robot")),
]


@pytest.mark.parametrize("rules, identity", IDENTITY_TABLE)
def test_node_name_and_namespace_remapping_read_as_rcl_reads_them(rules, identity):
    name, namespace, _ = node_identity(parse_ros_args([a for r in rules for a in ("-r", r)])["remap"])
    assert (name, namespace) == identity


def test_a_node_name_rcl_would_refuse_is_one_line():
    with pytest.raises(UsageError, match="a node name is letters, digits and underscores"):
        node_identity({"__node": "9 lives"})


# (name, rules) -> the name the node uses, in node arm_sim of namespace /ns (rcl_remap_topic_name)
NAME_TABLE = [
    ("joint_states", {}, "/ns/joint_states"), ("/clock", {}, "/clock"),
    ("~/reset", {}, "/ns/arm_sim/reset"),
    ("joint_states", {"joint_states": "js"}, "/ns/js"),        # relative both sides
    ("joint_states", {"/ns/joint_states": "/js"}, "/js"),      # matched after expansion
    ("~/reset", {"/ns/arm_sim/reset": "restart"}, "/ns/restart"),
    ("~/reset", {"~/reset": "~/restart"}, "/ns/arm_sim/restart"),
    ("joint_states", {"/joint_states": "/js"}, "/ns/joint_states"),   # another name
]


@pytest.mark.parametrize("name, rules, resolved", NAME_TABLE)
def test_topic_and_service_names_are_expanded_then_remapped(name, rules, resolved):
    assert remap_name(name, "arm_sim", "/ns", rules) == resolved


def test_use_sim_time_true_is_refused_on_dds_and_false_is_accepted():
    assert node_parameters(parse_ros_args(["-p", "use_sim_time:=false"]), "arm_sim", "/") == {}
    with pytest.raises(UsageError, match="use_sim_time:=true is not supported"):
        node_parameters(parse_ros_args(["-p", "use_sim_time:=true"]), "arm_sim", "/")


@pytest.mark.parametrize("text, expected", RCL_TABLE)
def test_rclpy_types_the_table_the_same_way(text, expected):
    rclpy = pytest.importorskip("rclpy")
    context = rclpy.Context()
    rclpy.init(context=context, args=["--ros-args", "-p", f"x:={text}"])
    try:
        node = rclpy.create_node("rcl_table", context=context,
                                 automatically_declare_parameters_from_overrides=True)
        value = node.get_parameter("x").value
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    if isinstance(expected, list):
        value = list(value)
    assert type(value) is type(expected) and value == expected


# --- degrees: the one rule (test/physics/test_degrees.py) on the node's parameters -----------

@pytest.mark.parametrize("assignment, name, expected", [
    ("initial_positions:=[90deg, 0deg]", "initial_positions", [math.pi / 2, 0.0]),
    ("initial_positions:=90deg,-30deg", "initial_positions", [math.pi / 2, -math.pi / 6]),
    ("sensors.position_resolution:=[0.1deg, 0.1deg]", "sensors.position_resolution",
     [math.radians(0.1)] * 2),
    ("joint_limits.lower:=[-90deg, -150deg]", "joint_limits.lower",
     [-math.pi / 2, math.radians(-150)]),
])
def test_the_node_takes_degrees_where_arm_sim_does(assignment, name, expected):
    """It refused `90deg` ("must be a number, got '90deg'") and its error did not say why."""
    from arm_sim_ros.node.params.parameters import SPECS
    from arm_sim_ros.node.params.values import coerce

    (_, key, value), = parse_ros_args(["-p", assignment])["assignments"]
    assert coerce(SPECS[key], value) == pytest.approx(expected, rel=1e-15)


def test_a_key_that_is_no_angle_refuses_deg_on_the_node_saying_which_take_it():
    from arm_sim_ros.node.params.parameters import SPECS
    from arm_sim_ros.node.params.values import ParameterRefused, coerce

    with pytest.raises(ParameterRefused, match="only angles take deg, the keys in rad: "
                                               "initial_positions, "):
        coerce(SPECS["damping"], "5deg")


def test_a_list_that_mixes_degrees_and_numbers_says_how_to_write_it():
    with pytest.raises(UsageError, match=r"takes deg on every number: \[90deg, 0deg\]"):
        parsed("[90deg, 0]")


def test_an_empty_value_the_shell_stripped_says_how_to_keep_it():
    """scripts/run's own hint, `-p rerun_path:=""`, reaches rcl as `rerun_path:=`."""
    with pytest.raises(UsageError) as error:
        parse_ros_args(["-p", "rerun_path:="])
    assert str(error.value) == ("-p rerun_path:='' has no value; empty text is YAML's '', which "
                                "the shell must keep: -p \"rerun_path:=''\"")
    (_, _, value), = parse_ros_args(["-p", "rerun_path:=''"])["assignments"]
    assert value == ""
