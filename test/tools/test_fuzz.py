"""Fuzzing every way a person can hand us input: scene files (random YAML trees and values),
`arm-sim` arguments, and `--ros-args` for the node. Zero tracebacks: every run ends with an
exit code of 0 (done), 1 (a run that faulted) or 2 (refused), and a refusal is one line on
stderr. The property, not a list of cases: hypothesis looks for the input that breaks it.
"""
import math
import os
import string

import pytest
import yaml
from hypothesis import HealthCheck, given, settings, strategies as st

from arm_sim_ros.node.params.parameters import resolve_parameters
from arm_sim_ros.node.params.values import ParameterRefused
from arm_sim_ros.node.params.ros_args import node_parameters, parse_ros_args
from arm_sim_ros.physics.scene import FIELD_KINDS
from arm_sim_ros.tools import cli
from arm_sim_ros.usage import UsageError

pytestmark = pytest.mark.hunt   # every case here is a fuzz (scripts/test -m hunt)

# ARM_SIM_FUZZ_EXAMPLES=5000 for a longer hunt by hand; CI keeps to a minute.
FUZZ = settings(max_examples=int(os.environ.get("ARM_SIM_FUZZ_EXAMPLES", 150)), deadline=None,
                derandomize=not os.environ.get("ARM_SIM_FUZZ_EXAMPLES"),
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**400, 10**400),
                    st.sampled_from([0, 1, -1, 0.5, 1e-3, 1e308, 5e-324, 10**300]))
scalars = st.one_of(numbers, st.booleans(), st.none(),
                    st.text(string.printable, max_size=12),
                    st.sampled_from(["rk4", "dopri5", "constant", "command", "release", "1e-3",
                                     ".5", "0x1F", "!!python/object:os.system", "*a", "&a"]))
keys = st.one_of(st.sampled_from(sorted(FIELD_KINDS)),
                 st.sampled_from(["springs", "payload", "motors", "effort_limits",
                                  "controller_model", "stiffness", "mass", "gear_ratio"]),
                 st.text(string.ascii_letters + "_.", min_size=1, max_size=8))
yaml_trees = st.recursive(
    scalars, lambda inner: st.one_of(st.lists(inner, max_size=3),
                                     st.dictionaries(keys, inner, max_size=4)),
    max_leaves=12)


def ends_cleanly(code, err):
    assert code in (0, 1, 2), err
    if code == 2:
        assert len(err.strip().splitlines()) == 1 and err.startswith("arm-sim: error: "), err


@FUZZ
@given(tree=st.dictionaries(keys, yaml_trees, max_size=6))
def test_any_scene_file_runs_or_is_refused_in_one_line(tmp_path_factory, capsys, tree):
    path = tmp_path_factory.mktemp("scenes") / "fuzzed.yaml"
    path.write_text(yaml.safe_dump(tree, allow_unicode=True) if tree else "")
    code = cli.main(["run", "--scene", str(path), "--duration", "0.02", "--step", "0.01"])
    ends_cleanly(code, capsys.readouterr().err)


@FUZZ
@given(text=st.text(max_size=200))
def test_any_text_as_a_scene_file_is_refused_in_one_line(tmp_path_factory, capsys, text):
    path = tmp_path_factory.mktemp("scenes") / "text.yaml"
    path.write_text(text)
    code = cli.main(["run", "--scene", str(path), "--duration", "0.02", "--step", "0.01"])
    ends_cleanly(code, capsys.readouterr().err)


values = st.one_of(st.text(string.printable, max_size=10), numbers.map(str),
                   st.sampled_from(["", "-", "--", "nan", "inf", "1e-300", "1e300", "0,0",
                                    "1,2,3", "gravity=0", "springs.stiffness=1e6,1",
                                    "payload.mass=-1", "motors.inductance=0,0"]))
RUN_OPTIONS = ["--scene", "--step", "--set", "--duration", "--publish-rate"]
BATCH_OPTIONS = ["--scene", "--step", "--set", "--count", "--duration", "--threads", "--seed"]
ACCURACY_OPTIONS = ["--scene", "--set", "--duration", "--integrators", "--steps", "--tolerances"]


def argv_for(command, options):
    pair = st.tuples(st.sampled_from(options), values).map(list)
    return st.lists(pair, max_size=4).map(lambda pairs: [command] + sum(pairs, []))


def bounded(argv, work):
    """Keep the fuzzed work small: a run this test can afford (refusals come first)."""
    return argv + work


@FUZZ
@given(argv=argv_for("run", RUN_OPTIONS))
def test_run_arguments_end_cleanly(capsys, argv):
    if "--duration" not in argv:
        argv += ["--duration", "0.05"]
    try:
        code = cli.main(bounded(argv, ["--step", "0.01"]) if "--step" not in argv else argv)
    except SystemExit as exit_:             # --help
        code = exit_.code
    ends_cleanly(code, capsys.readouterr().err)


@FUZZ
@given(argv=argv_for("batch", BATCH_OPTIONS))
def test_batch_arguments_end_cleanly(capsys, argv):
    code = cli.main(argv + ["--count", "50", "--duration", "0.05"])
    ends_cleanly(code, capsys.readouterr().err)


@FUZZ
@given(argv=argv_for("accuracy", ACCURACY_OPTIONS))
def test_accuracy_arguments_end_cleanly_or_are_refused_before_work(capsys, argv):
    # Only argument sets refused up front are run to the end; the rest must at least parse.
    code = cli.main(argv + ["--integrators", "nonexistent"])
    ends_cleanly(code, capsys.readouterr().err)
    assert code == 2


ros_values = st.one_of(values, st.sampled_from(["[1.0, 0.5]", "[1, 2.0]", "[[1]]", "{a: 1}",
                                                "'quoted'", "0x10", "true", "[", "&a 1", "*a"]))
ros_names = st.one_of(st.sampled_from(["scene", "damping", "payload_mass", "step_size",
                                       "publish_rate", "joint_names", "use_sim_time",
                                       "initial_positions", "rerun_spawn"]),
                      st.text(string.ascii_letters + "_.", min_size=1, max_size=8))


@FUZZ
@given(assignments=st.lists(st.tuples(ros_names, ros_values), max_size=4),
       extra=st.lists(st.sampled_from(["-p", "-r", "--log-level", "--params-file", "-x",
                                       "foo:=bar", "__ns:=/a b"]), max_size=3))
def test_ros_args_resolve_or_are_refused_in_one_line(assignments, extra):
    argv = sum((["-p", f"{name}:={value}"] for name, value in assignments), []) + extra
    try:
        ros = parse_ros_args(argv)
        params = node_parameters(ros, "arm_sim", "/")
        config = resolve_parameters(params)
    except (UsageError, ParameterRefused) as error:
        assert "\n" not in str(error)
        return
    assert math.isfinite(config.scene.step_size)


# The environment ROS 2 users set: a node started with any of it runs or refuses in one line.
env_values = st.fixed_dictionaries({}, optional={
    "ROS_DOMAIN_ID": st.one_of(st.integers(-5, 300).map(str), st.text(string.printable, max_size=6)),
    "ROS_AUTOMATIC_DISCOVERY_RANGE": st.one_of(
        st.sampled_from(["SUBNET", "LOCALHOST", "OFF", "SYSTEM_DEFAULT", "", "localhost"]),
        st.text(string.ascii_letters, max_size=8)),
    "CYCLONEDDS_URI": st.one_of(
        st.sampled_from(["", "<bad", "file:///nonexistent.xml", "<CycloneDDS/>",
                         "<General><Interfaces><NetworkInterface name='nope0'/></Interfaces></General>",
                         "<Discovery><ParticipantIndex>none</ParticipantIndex></Discovery>"]),
        st.text(string.printable, max_size=20)),
    "ROS_STATIC_PEERS": st.sampled_from(["", "127.0.0.1", "not a host;;", "::1"]),
})


@settings(max_examples=int(os.environ.get("ARM_SIM_FUZZ_EXAMPLES", 150)) // 8, deadline=None,
          derandomize=not os.environ.get("ARM_SIM_FUZZ_EXAMPLES"),
          suppress_health_check=[HealthCheck.too_slow])
@given(env=env_values)
def test_the_node_under_any_ros_environment_runs_or_refuses_in_one_line(env):
    import subprocess
    import sys

    full = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "CYCLONEDDS"))}
    full.update({k: v.replace("\x00", "") for k, v in env.items()})
    if "ROS_DOMAIN_ID" not in env:
        full["ROS_DOMAIN_ID"] = "97"                      # away from the other tests' domains
    done = subprocess.run([sys.executable, "-m", "arm_sim_ros.node.main", "--transport", "dds",
                           "--duration", "0", "--quiet"], env=full, capture_output=True,
                          text=True, timeout=60)
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode in (0, 2), done.stderr
    if done.returncode == 2:
        assert len(done.stderr.strip().splitlines()) == 1, done.stderr
