"""URDF out: the URDF of a scene's arm, for robot_state_publisher, RViz and other simulators.

urdf.read_urdf reads it back to the same scene values (test/physics/test_urdf.py), and the shipped
urdf/two_link_arm.urdf is this module's output for the default scene. Only what a URDF can
say is written: the bare links (no payload, no rotor inertia), joint_limits' lower and upper,
effort_limits, damping and Coulomb friction; the rest stays in the scene.
"""
from __future__ import annotations

import re
from xml.sax.saxutils import quoteattr

from ...interface import JOINT_NAMES
from ..model import MAX_ANGLE
from ..scene import Scene, SceneError
from .read import NO_EFFORT_LIMIT

ROD_RADIUS = 0.02          # m: the links' cylinders
HOUSING_RADIUS = 0.06      # m: the shoulder's cylinder
# <limit> needs a velocity (urdfdom refuses one without); the physics sets no speed limit,
# so it writes a bound far above what a simulated scene reaches, which nothing enforces.
VELOCITY_LIMIT = 1000.0    # rad/s
# What XML 1.0 cannot carry at all, escaped or not (its Char production).
NOT_XML = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")
COLORS = (("link1_blue", "0.25 0.55 0.95 1"), ("link2_orange", "0.95 0.55 0.2 1"))

HEADER = """<?xml version="1.0"?>
<!--
  A planar two-link arm, written by `arm-sim urdf` (arm_sim_ros/physics/urdf/write.py) from a
  scene, which arm-sim's urdf option and the node's robot_description read back. Regenerate
  it rather than edit it: test/physics/test_urdf.py checks that urdf/two_link_arm.urdf is the
  default scene's.

  Frames (REP 103): base_link is the world, z up, gravity along -z. The fixed plane_joint
  turns the arm's plane upright: arm_plane's x, y and z are the physics' (x along link 1 at
  zero angles, y up, z out of the plane), so both joints turn about +z of arm_plane (the
  world's -y) and a positive angle is counter-clockwise seen from -y, as the physics
  measures it. A point (x, y) of the physics is (x, 0, y) in base_link; the joint angles are
  the physics' q1 (from the horizontal) and q2 (relative to link 1), unwrapped.
  Inertias: izz, about the plane's normal, is the physics' COM inertia; iyy = izz (a slender
  link); ixx, about the link's own axis, is a solid rod's of the visual's radius, at most izz.
-->
"""


def number(value: float) -> str:
    """Shortest text that reads back to the same double (0 for either zero)."""
    return "0" if value == 0 else repr(float(value))


def scene_to_urdf(scene: Scene, robot: str = "two_link_arm") -> str:
    """The URDF of `scene`'s arm: links base_link, arm_plane, link1, link2, tip; joints
    plane_joint (fixed), shoulder_joint, elbow_joint (continuous, or revolute with joint
    limits), tip_joint (fixed)."""
    if not robot or NOT_XML.search(robot):
        raise SceneError(f"robot name {robot!r}: XML cannot hold it (an empty name, or a "
                         "control character)")
    links = scene.links
    pair = scene.damping if isinstance(scene.damping, tuple) else (scene.damping,) * 2
    friction = scene.friction["coulomb"] if scene.friction else (0.0, 0.0)
    ranges = _ranges(scene)
    parts = [HEADER, f'<robot name={quoteattr(robot)}>\n',
             '  <material name="base_grey"><color rgba="0.6 0.6 0.6 1"/></material>\n']
    parts += [f'  <material name="{name}"><color rgba="{rgba}"/></material>\n'
              for name, rgba in COLORS]
    parts.append(f"""
  <!-- The world, fixed. -->
  <link name="base_link"/>

  <!-- Roll +90 deg: arm_plane's y (the physics' up) is the world's z. -->
  <joint name="plane_joint" type="fixed">
    <parent link="base_link"/>
    <child link="arm_plane"/>
    <origin xyz="0 0 0" rpy="{number(1.5707963267948966)} 0 0"/>
  </joint>

  <!-- The physics' plane; the shoulder's housing around its axis. -->
  <link name="arm_plane">
    <visual>
      <geometry><cylinder radius="{number(HOUSING_RADIUS)}" length="{number(HOUSING_RADIUS)}"/></geometry>
      <material name="base_grey"/>
    </visual>
  </link>
""")
    parents = ("arm_plane", "link1")
    offsets = (0.0, links.link_lengths[0])
    for i in (0, 1):
        parts.append(_joint(JOINT_NAMES[i], parents[i], f"link{i + 1}", offsets[i], ranges[i],
                            _effort(scene, i), pair[i],
                            friction[i]))
        parts.append(_link(f"link{i + 1}", links.link_lengths[i], links.link_masses[i],
                           links.com_distances[i], links.com_inertias[i], COLORS[i][0]))
    parts.append(f"""
  <!-- The end of link 2: the tip. -->
  <joint name="tip_joint" type="fixed">
    <parent link="link2"/>
    <child link="tip"/>
    <origin xyz="{number(links.link_lengths[1])} 0 0" rpy="0 0 0"/>
  </joint>

  <link name="tip"/>
</robot>
""")
    return "".join(parts)


def _ranges(scene: Scene):
    """(lower, upper) per joint, or None where the joint is unlimited (continuous)."""
    if not scene.joint_limits:
        return None, None
    limits = zip(scene.joint_limits["lower"], scene.joint_limits["upper"])
    return tuple(None if lo <= -MAX_ANGLE and hi >= MAX_ANGLE else (lo, hi)
                 for lo, hi in limits)


def _effort(scene: Scene, joint: int):
    """The joint's effort limit, or None where the scene sets none (see NO_EFFORT_LIMIT)."""
    if scene.effort_limits is None or scene.effort_limits[joint] >= NO_EFFORT_LIMIT:
        return None
    return scene.effort_limits[joint]


def _joint(name, parent, child, offset, bounds, effort, damping, friction) -> str:
    lines = [f'  <joint name="{name}" type="{"continuous" if bounds is None else "revolute"}">',
             f'    <parent link="{parent}"/>', f'    <child link="{child}"/>',
             f'    <origin xyz="{number(offset)} 0 0" rpy="0 0 0"/>', '    <axis xyz="0 0 1"/>']
    if bounds is not None or effort is not None:
        span = "" if bounds is None else f'lower="{number(bounds[0])}" upper="{number(bounds[1])}" '
        effort = NO_EFFORT_LIMIT if effort is None else effort
        lines.append(f'    <limit {span}effort="{number(effort)}" '
                     f'velocity="{number(VELOCITY_LIMIT)}"/>')
    if damping or friction:
        lines.append(f'    <dynamics damping="{number(damping)}" friction="{number(friction)}"/>')
    return "\n" + "\n".join(lines + ["  </joint>"]) + "\n"


def _link(name, length, mass, com, inertia, material) -> str:
    axial = min(0.5 * mass * ROD_RADIUS ** 2, inertia)
    return f"""
  <link name="{name}">
    <inertial>
      <origin xyz="{number(com)} 0 0" rpy="0 0 0"/>
      <mass value="{number(mass)}"/>
      <inertia ixx="{number(axial)}" ixy="0" ixz="0" iyy="{number(inertia)}" iyz="0" izz="{number(inertia)}"/>
    </inertial>
    <visual>
      <!-- A cylinder's axis is its z; pitched 90 deg it lies along the link's x. -->
      <origin xyz="{number(0.5 * length)} 0 0" rpy="0 {number(1.5707963267948966)} 0"/>
      <geometry><cylinder radius="{number(ROD_RADIUS)}" length="{number(length)}"/></geometry>
      <material name="{material}"/>
    </visual>
  </link>
"""
