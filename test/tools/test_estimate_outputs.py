"""Issue 35: every output of an `estimate: off` run says that it carries no error estimate:
`arm-sim run` (text and --json), the diagnostics (the node's and a --bag's) and the Rerun
recording's properties; `--estimate off` is the command line's way to it."""
import json
import logging

import pytest

from arm_sim_ros.node import core as node_core
from arm_sim_ros.node.params import parameters as node_params
from arm_sim_ros.node.params.ros_args import FALSE, TRUE, load_params_file
from arm_sim_ros.physics.scene import SceneError, load_scene
from arm_sim_ros.recording.rrd import readback
from arm_sim_ros.tools import cli

from recording.test_bag import read_bag

NO_ESTIMATE = "this run carries no error estimate"


def run_cli(capsys, *argv):
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_estimate_off_on_the_command_line_sets_the_tolerance_to_0_and_json_says_off(capsys):
    code, out, _ = run_cli(capsys, "run", "--scene", "damped_release", "--estimate", "off",
                           "--duration", "0.3", "--json")
    result = json.loads(out)
    assert code == 0 and result["estimate"] == "off"
    assert result["error_estimate"] is None and result["accumulated_error"] is None
    code, out, _ = run_cli(capsys, "run", "--scene", "damped_release", "--duration", "0.3",
                           "--json")
    assert json.loads(out)["estimate"] == "global"


def test_the_text_result_of_an_off_run_says_it_carries_no_error_estimate(capsys):
    code, out, _ = run_cli(capsys, "run", "--estimate", "off", "--duration", "0.1")
    assert code == 0
    assert out.splitlines()[-1] == f"error estimate: none (estimate off: {NO_ESTIMATE})"


# every way the command line names the two: one rule (`--set estimate=off --tolerance` dropped
# the tolerance unseen, while `--estimate off --tolerance` was refused)
@pytest.mark.parametrize("estimate", [["--set", "estimate=off"], ["--estimate", "off"]])
@pytest.mark.parametrize("tolerance", [["--set", "tolerance=1e-6"], ["--tolerance", "1e-6"]])
@pytest.mark.parametrize("tolerance_first", [False, True])
def test_estimate_off_with_a_tolerance_is_refused_in_one_line(capsys, estimate, tolerance,
                                                              tolerance_first):
    argv = tolerance + estimate if tolerance_first else estimate + tolerance
    code, out, err = run_cli(capsys, "run", "--duration", "0.1", *argv)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "estimate off computes no error estimate" in err


@pytest.mark.parametrize("argv", [["--set", "estimate=off"],
                                  ["--set", "estimate=off", "--set", "tolerance=0"]])
def test_estimate_off_alone_or_with_tolerance_0_runs(capsys, argv):
    code, out, _ = run_cli(capsys, "run", "--duration", "0.1", *argv, "--json")
    assert code == 0 and json.loads(out)["estimate"] == "off"


@pytest.mark.parametrize("word", sorted(TRUE | FALSE))
def test_a_scene_file_and_a_parameter_file_read_estimate_off_alike(tmp_path, word):
    """`estimate: off` as the docs write it: YAML reads the bare word as a bool (rcl reads
    y and n as bools too); a scene file and the node's --params-file take every such word
    alike, as `off` where it means false and refused where it means true."""
    (tmp_path / "s.yaml").write_text(f"estimate: {word}\n")
    (tmp_path / "p.yaml").write_text(f"arm_sim:\n  ros__parameters:\n    estimate: {word}\n")
    try:
        scene = load_scene(str(tmp_path / "s.yaml")).estimate
    except SceneError as refused:
        scene = ("refused", str(refused).partition("): ")[2])    # after "scene 's' (path)"
    try:
        node = node_params.resolve_parameters(load_params_file(str(tmp_path / "p.yaml")))
        node = node.scene.estimate
    except node_params.ParameterRefused as refused:
        node = ("refused", refused.reason)
    assert scene == node
    assert scene == "off" if word in FALSE else "got True (a bare" in scene[1]


def test_the_bag_diagnostics_of_an_off_run_say_it(capsys, tmp_path):
    code, _, err = run_cli(capsys, "run", "--scene", "damped_release", "--estimate", "off",
                           "--duration", "1", "--bag", str(tmp_path / "bag"))
    assert code == 0, err
    messages, _ = read_bag(tmp_path / "bag")
    for _, message, _ in messages["/diagnostics"]:
        values = {kv.key: kv.value for kv in message.status[0].values}
        assert values["estimate"] == f"off: {NO_ESTIMATE}"
        assert values["error_estimate"] == values["accumulated_error"] == "nan"


def test_the_recording_of_an_off_run_says_it_in_its_properties(capsys, tmp_path):
    path = tmp_path / "off.rrd"
    code, _, err = run_cli(capsys, "run", "--estimate", "off", "--duration", "0.2",
                           "--rerun", str(path))
    assert code == 0, err
    props = readback.properties(path)
    assert props["estimate"]["mode"] == "off"
    assert props["estimate"]["meaning"].startswith(NO_ESTIMATE)
    assert props["scene"]["estimate"] == "off" and props["scene"]["tolerance"] == 0.0
    code, _, _ = run_cli(capsys, "run", "--duration", "0.2", "--rerun", str(tmp_path / "g.rrd"))
    assert readback.properties(tmp_path / "g.rrd")["estimate"]["mode"] == "global"


def test_the_node_takes_estimate_as_a_parameter_and_its_diagnostics_say_off():
    config = node_params.resolve_parameters({"estimate": "off", "tolerance": 0.0})
    assert config.scene.estimate == "off"
    node = node_core.ArmSimCore(config, logging.getLogger("estimate"))
    node.tick()
    values = dict(node.diagnostics().values)
    assert values["estimate"] == f"off: {NO_ESTIMATE}" and values["error_estimate"] == "nan"
    default = node_core.ArmSimCore(node_params.resolve_parameters({}), logging.getLogger("e"))
    assert dict(default.diagnostics().values)["estimate"] == "global"


def test_the_node_refuses_estimate_off_beside_a_tolerance_naming_the_parameter():
    with pytest.raises(node_params.ParameterRefused) as refused:
        node_params.resolve_parameters({"estimate": "off", "tolerance": 5e-05})
    assert refused.value.name == "tolerance"          # the one to set to 0 or leave out
    assert "cannot hold tolerance = 5e-05" in refused.value.reason
    alone = node_params.resolve_parameters({"estimate": "off"})    # off alone: no tolerance
    assert alone.scene.estimate == "off" and alone.scene.tolerance == 0.0
    config = node_params.resolve_parameters({"scene": "damped_release"})
    assert config.with_changes({"tolerance": 0.0, "estimate": "off"}).scene.estimate == "off"
    assert load_scene("damped_release").estimate == "global"


def latest_view_names(path) -> set:
    """The names of the views of the recording's latest blueprint (one is sent again where
    the layout changes): those its viewport's root container holds, container by container."""
    import uuid

    import rerun as rr
    reader = rr.chunk.RrdReader(str(path))
    (store,) = reader.blueprints()
    rows, roots = {}, []
    for chunk in reader.stream(store=store):
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name == "ViewportBlueprint:root_container":
                roots += batch.column(name).to_pylist()
            elif name in ("ContainerBlueprint:contents", "ViewBlueprint:display_name"):
                rows[chunk.entity_path] = batch.column(name).to_pylist()[-1]
    names, todo = set(), [f"/container/{uuid.UUID(bytes=bytes(roots[-1][0]))}"]
    while todo:
        entity = todo.pop()
        if entity.startswith("/view/"):
            names.add(rows[entity][0])
        else:
            todo += ["/" + child for child in rows[entity]]
    return names


@pytest.mark.parametrize("first, then", [("global", "off"), ("off", "global")])
def test_a_recording_switched_live_says_both_modes_and_keeps_its_estimates(tmp_path, first,
                                                                           then):
    """A node switched live from global to off holds the estimates made until the switch:
    its recording says both modes in order, keeps the estimate panes, and labels none of
    its steps "no error estimate"; the other way round alike."""
    path = tmp_path / "switched.rrd"
    node = node_core.ArmSimCore(node_params.resolve_parameters(
        {"scene": "damped_release", "estimate": first, "rerun_path": str(path)}),
        logging.getLogger("switched"))
    for _ in range(40):
        node.tick()
    node.set_parameters({"estimate": then})
    for _ in range(40):
        node.tick()
    node.finish()
    estimate = readback.properties(path)["estimate"]
    assert estimate["mode"] == f"{first}, then {then}"
    assert estimate["meaning"].index(f"{first}:") < estimate["meaning"].index(f"then {then}:")
    views = latest_view_names(path)
    assert any(name.startswith("Local error per step") for name in views)
    assert not any("no error estimate" in name for name in views)
