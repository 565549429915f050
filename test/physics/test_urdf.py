"""URDF in and out (physics/urdf/read.py, physics/urdf/write.py): urdf/two_link_arm.urdf is the
default scene's arm, generated, never hand-edited; a planar 2R URDF reads into a scene and
back unchanged; the arm stands upright in a z-up world (RViz's view) with the physics'
angles; anything that is not a planar 2R arm is refused with one line saying why."""
import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from arm_sim_ros.interface import JOINT_NAMES
from arm_sim_ros.node.params.parameters import SPECS, resolve_parameters
from arm_sim_ros.node.params.values import ParameterRefused
from arm_sim_ros.physics.model import (ArmParameters, gravity_torque, link_points, mass_matrix,
                                       potential_energy)
from arm_sim_ros.physics.model import MAX_ANGLE
from arm_sim_ros.physics.scene import Scene, SceneError, load_scene, preset_names
from arm_sim_ros.physics.urdf import read as urdf
from arm_sim_ros.physics.urdf.read import NO_EFFORT_LIMIT, read_urdf, scene_from_urdf
from arm_sim_ros.physics.urdf.write import scene_to_urdf
from arm_sim_ros.tools import cli

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = (ROOT / "urdf" / "two_link_arm.urdf").read_text()
FRAGMENT = (ROOT / "urdf" / "two_link_arm.ros2_control.xml").read_text()
DEFAULT = load_scene(SPECS["scene"].default)
POSES = [(0.0, 0.0), (0.6, 0.8), (math.pi / 2, 0.0), (-1.2, 2.0), (2.5, -0.7), (7.0, -9.0)]

# The same kind of arm written another way: a world link, a massive pedestal fixed to it,
# joint axes along -y with no plane frame, a rotated inertia frame, a revolute shoulder beside a
# continuous elbow, an off-line camera frame and a tool frame at the tip.
OTHER = """<?xml version="1.0"?>
<robot name="pendulum">
  <link name="world"/>
  <joint name="mount" type="fixed"><parent link="world"/><child link="pedestal"/>
    <origin xyz="0.2 -0.1 2.5"/></joint>
  <link name="pedestal"><inertial><mass value="10"/>
    <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <joint name="hip" type="revolute"><parent link="pedestal"/><child link="upper"/>
    <axis xyz="0 -2 0"/><limit lower="-2" upper="2.5" effort="40" velocity="5"/>
    <dynamics damping="0.1" friction="0.2"/></joint>
  <link name="upper"><inertial><origin xyz="0.3 0 0" rpy="1.5707963267948966 0 0"/>
    <mass value="2"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.2"/>
  </inertial></link>
  <joint name="knee" type="continuous"><parent link="upper"/><child link="lower"/>
    <origin xyz="0.7 0 0"/><axis xyz="0 -1 0"/><limit effort="10" velocity="5"/></joint>
  <link name="lower"><inertial><origin xyz="0.25 0 0"/><mass value="0.5"/>
    <inertia ixx="0.0001" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="camera_mount" type="fixed"><parent link="lower"/><child link="camera"/>
    <origin xyz="0.2 0 0.05"/></joint>
  <link name="camera"/>
  <joint name="tool" type="fixed"><parent link="lower"/><child link="tool0"/>
    <origin xyz="0.6 0 0"/></joint>
  <link name="tool0"/>
</robot>
"""


# --- the shipped file is the generator's output -------------------------------------------

def test_the_shipped_urdf_is_the_default_scenes_generated_urdf():
    assert SHIPPED == scene_to_urdf(DEFAULT), "regenerate: arm-sim urdf -o urdf/two_link_arm.urdf --force"


def test_the_shipped_urdf_reads_back_as_the_explainers_arm():
    scene = scene_from_urdf(SHIPPED, Scene(link_lengths=(3.0, 2.0), link_masses=(5.0, 5.0)))
    assert scene.links == ArmParameters() == DEFAULT.links
    m11, m12, m22 = mass_matrix(scene.arm, (0.0, 0.7))
    assert (m11, m12, m22) == pytest.approx((5 / 3 + math.cos(0.7), 1 / 3 + math.cos(0.7) / 2, 1 / 3))
    assert (scene.damping, scene.friction, scene.effort_limits, scene.joint_limits) == \
        (0.0, None, None, None)


def test_the_moving_joints_are_the_nodes_and_the_ros2_control_fragments():
    arm = read_urdf(SHIPPED)
    assert arm.joint_names == tuple(SPECS["joint_names"].default) == JOINT_NAMES
    fragment = [j.get("name") for j in ET.fromstring(FRAGMENT).findall("joint")]
    assert fragment == list(arm.joint_names)
    # the launch file appends the fragment: the node reads the combined description alike
    combined = SHIPPED.replace("</robot>", FRAGMENT + "</robot>")
    assert read_urdf(combined) == arm


def test_the_chain_keeps_its_names_from_base_link_to_tip():
    robot = ET.fromstring(SHIPPED)
    chain = [(j.get("name"), j.find("parent").get("link"), j.find("child").get("link"))
             for j in robot.iter("joint")]
    assert chain == [("plane_joint", "base_link", "arm_plane"), ("shoulder_joint", "arm_plane", "link1"),
                     ("elbow_joint", "link1", "link2"), ("tip_joint", "link2", "tip")]


# --- round trips --------------------------------------------------------------------------

@pytest.mark.parametrize("name", preset_names())
def test_every_preset_goes_to_urdf_and_back_unchanged(name):
    scene = load_scene(name)
    text = scene_to_urdf(scene)
    assert scene_from_urdf(text, scene) == scene
    assert scene_to_urdf(scene_from_urdf(text, Scene())) == text
    for inertia in ET.fromstring(text).iter("inertia"):   # a body other simulators accept
        ixx, iyy, izz = (float(inertia.get(k)) for k in ("ixx", "iyy", "izz"))
        assert min(ixx, iyy, izz) >= 0 and ixx + iyy >= izz and iyy + izz >= ixx and izz + ixx >= iyy


def test_an_uneven_arm_with_one_limited_joint_round_trips():
    scene = Scene(link_lengths=(0.8, 1.3), link_masses=(2.5, 0.7), com_distances=(0.3, 0.9),
                  com_inertias=(0.02, 0.0), damping=(0.1, 0.4), effort_limits=(30.0, NO_EFFORT_LIMIT),
                  friction={"coulomb": [0.5, 0.0]},
                  joint_limits={"lower": [-1.0, -MAX_ANGLE], "upper": [2.0, MAX_ANGLE],
                                "restitution": 0.5})
    text = scene_to_urdf(scene)
    shoulder, elbow = (j for j in ET.fromstring(text).iter("joint") if j.get("name") in JOINT_NAMES)
    assert (shoulder.get("type"), elbow.get("type")) == ("revolute", "continuous")
    assert elbow.find("limit") is None             # unlimited effort, unlimited angle
    assert scene_from_urdf(text, scene) == scene
    back = scene_from_urdf(text, Scene())           # restitution is not URDF's to say
    assert back.joint_limits == {"lower": (-1.0, -MAX_ANGLE),
                                 "upper": (2.0, MAX_ANGLE)}
    assert scene_to_urdf(back) == text


def test_the_urdf_decides_what_it_can_say_and_the_base_scene_the_rest():
    base = load_scene("damped_release").replace(gravity=3.0, initial_positions=(0.2, 0.1))
    scene = scene_from_urdf(OTHER, base)
    assert scene.links == ArmParameters(link_lengths=(0.7, 0.6), link_masses=(2.0, 0.5),
                                        com_distances=(0.3, 0.25), com_inertias=(0.2, 0.01))
    assert scene.damping == (0.1, 0.0)
    assert scene.friction == {"coulomb": (0.2, 0.0), "stribeck_velocity": 0.0}
    assert scene.effort_limits == (40.0, 10.0)
    assert scene.joint_limits == {"lower": (-2.0, -MAX_ANGLE),
                                  "upper": (2.5, MAX_ANGLE)}
    assert (scene.gravity, scene.initial_positions, scene.step_size, scene.name) == \
        (3.0, (0.2, 0.1), base.step_size, base.name)
    assert read_urdf(OTHER).joint_names == ("hip", "knee")
    # no <dynamics>: URDF's zero damping, whatever the base scene had
    assert scene_from_urdf(SHIPPED, base).damping == 0.0


# --- upright in a z-up world, the physics' angles -----------------------------------------

def rotation(axis, angle):
    """Rodrigues' rotation about a unit axis."""
    k = np.array(axis, float) / np.linalg.norm(axis)
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * cross + (1 - math.cos(angle)) * cross @ cross


def frames(text, angles):
    """Every link's world pose (R, p) with the moving joints at `angles` (by joint name):
    URDF's origins (rpy about fixed x, y, z) and axes composed from the root."""
    robot = ET.fromstring(text)
    joints = {j.find("child").get("link"): j for j in robot.iter("joint")}
    poses = {}

    def pose(link):
        if link not in joints:
            return np.eye(3), np.zeros(3)
        j = joints[link]
        parent_r, parent_p = pose(j.find("parent").get("link"))
        origin = j.find("origin")
        xyz = [float(v) for v in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()]
        r, p, y = [float(v) for v in (origin.get("rpy", "0 0 0") if origin is not None else "0 0 0").split()]
        local = rotation((0, 0, 1), y) @ rotation((0, 1, 0), p) @ rotation((1, 0, 0), r)
        if j.get("name") in angles:
            local = local @ rotation([float(v) for v in j.find("axis").get("xyz").split()],
                                     angles[j.get("name")])
        return parent_r @ local, parent_p + parent_r @ np.array(xyz)

    for link in {l.get("name") for l in robot.iter("link")}:
        poses[link] = pose(link)
    return poses


@pytest.mark.parametrize("text, tip", [(SHIPPED, "tip"), (OTHER, "tool0")])
@pytest.mark.parametrize("q", POSES)
def test_the_urdf_chain_puts_the_physics_plane_upright(text, tip, q):
    # A physics point (x, y) is the world's (x, 0, y) from the shoulder: x right, y up = z.
    arm = read_urdf(text)
    scene = scene_from_urdf(text, Scene())
    links = [l for l in (j.find("child").get("link") for j in ET.fromstring(text).iter("joint")
                         if j.get("name") in arm.joint_names)]
    poses = frames(text, dict(zip(arm.joint_names, q)))
    shoulder = poses[links[0]][1]
    _, elbow, end = link_points(scene.arm, q)
    assert poses[links[1]][1] - shoulder == pytest.approx([elbow[0], 0.0, elbow[1]], abs=1e-12)
    assert poses[tip][1] - shoulder == pytest.approx([end[0], 0.0, end[1]], abs=1e-12)
    # gravity along the world's -z: the centres of mass' heights give the physics' V(q)
    height = [float((r @ np.array([c, 0.0, 0.0]) + p - shoulder)[2]) for (r, p), c in
              zip((poses[l] for l in links), arm.com_distances)]
    assert 9.81 * sum(m * h for m, h in zip(arm.link_masses, height)) == \
        pytest.approx(potential_energy(scene.arm, q, 9.81), abs=1e-12)


def test_positive_angles_turn_counter_clockwise_seen_from_minus_y():
    # q1 = +90 deg lifts link 1 straight up; the joint axes point at a viewer on -y.
    poses = frames(SHIPPED, {"shoulder_joint": math.pi / 2, "elbow_joint": 0.0})
    assert poses["link2"][1] == pytest.approx([0.0, 0.0, 1.0], abs=1e-12)
    assert poses["link1"][0] @ np.array([0.0, 0.0, 1.0]) == pytest.approx([0.0, -1.0, 0.0], abs=1e-12)


def test_mujoco_reads_the_shipped_urdf_as_the_physics_arm_under_gravity_minus_z():
    mujoco = pytest.importorskip("mujoco")     # an independent URDF reader and rigid-body code
    model = mujoco.MjModel.from_xml_string(SHIPPED)
    data = mujoco.MjData(model)
    assert [model.joint(i).name for i in range(model.njnt)] == list(JOINT_NAMES)
    assert list(model.opt.gravity) == [0.0, 0.0, -9.81]
    for q in POSES:
        data.qpos[:] = q
        mujoco.mj_forward(model, data)
        full = np.zeros((2, 2))
        mujoco.mj_fullM(model, data, full)
        m11, m12, m22 = mass_matrix(DEFAULT.arm, q)
        assert full == pytest.approx(np.array([[m11, m12], [m12, m22]]), abs=1e-12)
        assert data.qfrc_bias == pytest.approx(gravity_torque(DEFAULT.arm, q, 9.81), abs=1e-12)


# --- refusals: one line, why -------------------------------------------------------------

def edit(text, anchor, old, new):
    """`text` with the first `old` after `anchor` replaced by `new`."""
    start = text.index(anchor)
    at = text.index(old, start)
    return text[:at] + new + text[at + len(old):]


PLANE_RPY = 'rpy="1.5707963267948966 0 0"'
REFUSED = [
    ("", "empty"),
    (SHIPPED[:-12], "not well-formed XML"),
    ('<?xml version="1.0"?><model name="x"/>', "<model>, not <robot>"),
    (SHIPPED.replace('xyz="1.0 0 0" rpy="0 0 0"', 'xyz="${l1} 0 0" rpy="0 0 0"', 1), "xacro"),
    (edit(SHIPPED, '"elbow_joint"', 'type="continuous"', 'type="fixed"'), "1 revolute or continuous"),
    (edit(SHIPPED, '"tip_joint"', 'type="fixed"', 'type="revolute"'), "3 revolute or continuous"),
    (edit(SHIPPED, '"elbow_joint"', 'type="continuous"', 'type="prismatic"'), "is prismatic"),
    (edit(SHIPPED, '"elbow_joint"', '<axis xyz="0 0 1"/>', '<axis xyz="0 1 1"/>'), "not parallel"),
    (edit(SHIPPED, '"elbow_joint"', '<axis xyz="0 0 1"/>', '<axis xyz="0 0 -1"/>'), "opposite"),
    (SHIPPED.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 -1"/>'), "reverse both joint axes"),
    (SHIPPED.replace(PLANE_RPY, 'rpy="0 0 0"'), "is vertical"),
    (SHIPPED.replace(PLANE_RPY, 'rpy="1.2 0 0"'), "off the horizontal"),
    (edit(SHIPPED, '"shoulder_joint"', 'rpy="0 0 0"', 'rpy="0 0 -1.5707963267948966"'),
     "90° below the horizontal"),
    (edit(SHIPPED, '"elbow_joint"', 'xyz="1.0 0 0"', 'xyz="1.0 0 0.1"'), "0.1 m out of the plane"),
    (edit(SHIPPED, '"link1"', 'xyz="0.5 0 0"', 'xyz="0.5 0.05 0"'), "off the link's line"),
    (edit(SHIPPED, '<link name="link2"', '<mass value="1.0"/>', ""), "link2 has no <inertial> mass"),
    (SHIPPED.replace('<link name="tip"/>', '<link name="tip"><inertial><mass value="0.2"/>'
                     '<inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>'),
     "fold it into link2"),
    (edit(SHIPPED, '"shoulder_joint"', "</joint>", '<limit effort="5"/></joint>'), "no velocity"),
    (edit(SHIPPED, '"shoulder_joint"', 'type="continuous"', 'type="revolute"'), "has no <limit>"),
    (edit(SHIPPED, '"shoulder_joint"', "</joint>", '<limit effort="0" velocity="1"/></joint>'),
     "effort_limits[0] = 0 is impossible"),
    (edit(edit(SHIPPED, '"shoulder_joint"', 'type="continuous"', 'type="revolute"'),
          '"shoulder_joint"', "</joint>", '<limit lower="1" upper="-1" effort="5" velocity="1"/></joint>'),
     "must be below"),
    (edit(SHIPPED, '"shoulder_joint"', "</joint>", '<dynamics damping="-1"/></joint>'), "would add energy"),
    (SHIPPED.replace('<link name="tip"/>', '<link name="tip"/><link name="stray"/>'), "2 root links"),
    (edit(SHIPPED, '"elbow_joint"', '<parent link="link1"/>', '<parent link="arm_plane"/>'),
     "separate branches"),
    (edit(SHIPPED, '"elbow_joint"', '<parent link="link1"/>', '<parent link="nowhere"/>'),
     "does not have"),
    (edit(SHIPPED, '"elbow_joint"', 'xyz="1.0 0 0"', 'xyz="nan 0 0"'), "not three finite numbers"),
    (edit(SHIPPED, '"elbow_joint"', '<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>'), "zero <axis>"),
    (edit(SHIPPED, '"elbow_joint"', 'xyz="1.0 0 0"', 'xyz="0 0 0"'), "no length"),
]


@pytest.mark.parametrize("text, reason", REFUSED, ids=[r for _, r in REFUSED])
def test_what_is_not_a_planar_2r_arm_is_refused_with_one_line_saying_why(text, reason):
    with pytest.raises(SceneError) as refused:
        scene_from_urdf(text, DEFAULT)
    message = str(refused.value)
    assert reason in message and "\n" not in message and message.startswith("URDF")


def test_rounding_in_a_hand_written_urdf_is_not_a_refusal():
    # 1.5708 for pi/2 puts the plane 4e-6 rad off vertical: within TOLERANCE
    scene = scene_from_urdf(SHIPPED.replace(PLANE_RPY, 'rpy="1.5708 0 0"'), DEFAULT)
    assert scene.links == DEFAULT.links


# --- arm-sim urdf, arm-sim --urdf ---------------------------------------------------------

def test_arm_sim_urdf_prints_the_shipped_file_and_writes_one_with_o(tmp_path, capsys):
    assert cli.main(["urdf"]) == 0
    assert capsys.readouterr().out == SHIPPED
    out = tmp_path / "arm.urdf"
    assert cli.main(["urdf", "--scene", "limit_impact", "-o", str(out)]) == 0
    assert out.read_text() == scene_to_urdf(load_scene("limit_impact"))
    assert cli.main(["urdf", "-o", str(out)]) == 2          # exists: refused, unchanged
    assert "exists already" in capsys.readouterr().err
    assert out.read_text() == scene_to_urdf(load_scene("limit_impact"))


def test_run_with_urdf_simulates_the_urdfs_arm_on_the_scenes_rest(tmp_path, capsys):
    arm = {"link_lengths": "0.8,1.2", "com_distances": "0.3,0.7", "link_masses": "2,0.5"}
    sets = [a for k, v in arm.items() for a in ("--set", f"{k}={v}")]
    path = tmp_path / "arm.urdf"
    assert cli.main(["urdf", *sets, "-o", str(path)]) == 0
    capsys.readouterr()
    assert cli.main(["run", "--scene", "moving_gravity_compensation", "--urdf", str(path), "--json"]) == 0
    from_urdf = json.loads(capsys.readouterr().out)
    assert cli.main(["run", "--scene", "moving_gravity_compensation", *sets, "--json"]) == 0
    assert from_urdf == json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("text, reason", [(None, "cannot read it"), ("<robot", "not well-formed"),
                                           (REFUSED[9][0], "reverse both joint axes")])
def test_a_bad_urdf_file_is_one_line_and_exit_2(tmp_path, capsys, text, reason):
    path = tmp_path / "bad.urdf"
    if text is not None:
        path.write_text(text)
    for command in ("run", "batch", "accuracy", "urdf"):
        assert cli.main([command, "--urdf", str(path)]) == 2
        err = capsys.readouterr().err
        assert reason in err and err.count("\n") == 1 and "Traceback" not in err


# --- the node's robot_description ----------------------------------------------------------

def test_the_nodes_robot_description_is_read_into_its_scene_and_joint_names():
    config = resolve_parameters({"robot_description": OTHER})
    # (the node serves an unpowered scene as policy "command": it listens out of the box)
    assert config.scene == scene_from_urdf(OTHER, DEFAULT).replace(policy="command")
    assert config.values["joint_names"] == list(read_urdf(OTHER).joint_names)


def test_parameters_given_beside_robot_description_still_override_it():
    config = resolve_parameters({"robot_description": OTHER, "damping": 0.25,
                                 "joint_names": ["a", "b"]})
    assert config.scene.damping == 0.25 and config.values["joint_names"] == ["a", "b"]


def test_no_robot_description_leaves_the_scenes_arm():
    assert resolve_parameters({}).scene == DEFAULT.replace(policy="command")


def test_a_robot_description_that_is_not_a_planar_2r_arm_is_refused_naming_it():
    with pytest.raises(ParameterRefused, match="robot_description.*URDF"):
        resolve_parameters({"robot_description": "<robot name='empty'/>"})


def test_robot_description_is_chosen_at_start():
    with pytest.raises(ParameterRefused, match="robot_description"):
        resolve_parameters({}).with_changes({"robot_description": OTHER})


# --- size: a description is bounded, and read in time linear in its links ----------------------

def _with_fixed_chain(count):
    text = (ROOT / "urdf" / "two_link_arm.urdf").read_text()
    chain = "".join(
        f'<link name="f{i}"/><joint name="jf{i}" type="fixed"><parent link="'
        f'{"f%d" % (i - 1) if i else "link2"}"/><child link="f{i}"/></joint>'
        for i in range(count))
    return text.replace("</robot>", chain + "</robot>")


def test_a_urdf_beyond_the_size_caps_is_refused_in_one_line():
    with pytest.raises(SceneError, match="20005 links"):
        urdf.read_urdf(_with_fixed_chain(20_000))
    with pytest.raises(SceneError, match="characters"):
        urdf.read_urdf("<robot>" + " " * (urdf.MAX_URDF_CHARS + 1) + "</robot>")


def test_a_long_chain_of_fixed_links_is_read_as_the_arm_without_them():
    plain = urdf.read_urdf((ROOT / "urdf" / "two_link_arm.urdf").read_text())
    chained = urdf.read_urdf(_with_fixed_chain(urdf.MAX_LINKS - 10))
    assert chained.link_masses == plain.link_masses and chained.joint_names == plain.joint_names


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(st.text())
def test_any_robot_name_is_well_formed_xml_or_refused_in_one_line(robot):
    """`arm-sim urdf --robot '<&>"'` wrote XML that was not well-formed, with exit 0."""
    try:
        text = scene_to_urdf(load_scene("release"), robot=robot)
    except SceneError as error:
        assert "XML cannot hold it" in str(error)
        return
    assert ET.fromstring(text.encode()).get("name") == robot      # escaped, read back
