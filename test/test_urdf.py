"""urdf/two_link_arm.urdf describes the arm the simulator integrates: the explainer's rods."""
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from arm_sim_ros.physics.model import ArmParameters
from arm_sim_ros.node.parameters import SPECS

URDF = Path(__file__).resolve().parents[1] / "urdf" / "two_link_arm.urdf"
ARM = ArmParameters()
LINKS = ("link1", "link2")


@pytest.fixture(scope="module")
def robot():
    return ET.parse(URDF).getroot()


def joint(robot, name):
    return next(j for j in robot.iter("joint") if j.get("name") == name)


def floats(text):
    return [float(v) for v in text.split()]


def test_the_moving_joints_are_the_nodes_default_joint_names(robot):
    moving = [j.get("name") for j in robot.iter("joint") if j.get("type") != "fixed"]
    assert moving == SPECS["joint_names"].default == ["shoulder_joint", "elbow_joint"]


@pytest.mark.parametrize("name", ["shoulder_joint", "elbow_joint"])
def test_joints_turn_about_z_without_limits(robot, name):
    # continuous = revolute without position limits: the simulated angles stay unwrapped.
    j = joint(robot, name)
    assert j.get("type") == "continuous"
    assert floats(j.find("axis").get("xyz")) == [0.0, 0.0, 1.0]
    assert floats(j.find("origin").get("rpy")) == [0.0, 0.0, 0.0]


def test_chain_is_base_link1_link2_tip(robot):
    chain = [(j.find("parent").get("link"), j.find("child").get("link")) for j in robot.iter("joint")]
    assert chain == [("base_link", "link1"), ("link1", "link2"), ("link2", "tip")]
    assert joint(robot, "tip_joint").get("type") == "fixed"


def test_link_lengths_are_the_joint_offsets_along_x(robot):
    # Zero pose: both links along +x, so each length is the next joint's x offset.
    assert floats(joint(robot, "shoulder_joint").find("origin").get("xyz")) == [0.0, 0.0, 0.0]
    for name, length in zip(("elbow_joint", "tip_joint"), ARM.link_lengths):
        assert floats(joint(robot, name).find("origin").get("xyz")) == [length, 0.0, 0.0]


@pytest.mark.parametrize("index", [0, 1])
def test_masses_centres_of_mass_and_inertias_equal_the_model(robot, index):
    link = next(l for l in robot.iter("link") if l.get("name") == LINKS[index])
    inertial = link.find("inertial")
    assert float(inertial.find("mass").get("value")) == ARM.link_masses[index]
    assert floats(inertial.find("origin").get("xyz")) == [ARM.com_distances[index], 0.0, 0.0]
    inertia = inertial.find("inertia").attrib
    assert float(inertia["izz"]) == pytest.approx(ARM.com_inertias[index], rel=1e-15)
    assert all(float(inertia[k]) == 0.0 for k in ("ixy", "ixz", "iyz"))
    # A physical body: positive principal moments obeying the triangle inequality.
    ixx, iyy, izz = (float(inertia[k]) for k in ("ixx", "iyy", "izz"))
    assert min(ixx, iyy, izz) > 0
    assert ixx + iyy >= izz and iyy + izz >= ixx and izz + ixx >= iyy


def test_base_link_is_the_fixed_root(robot):
    children = {j.find("child").get("link") for j in robot.iter("joint")}
    roots = [l.get("name") for l in robot.iter("link") if l.get("name") not in children]
    assert roots == ["base_link"]
