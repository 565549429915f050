"""URDF in: a planar two-link arm (2R) described in URDF, read into a scene.

How the URDF's frames map onto the physics' plane. The URDF's root link is the world, as
REP 103 has it: z up, gravity along −z. The arm's plane must be vertical and the angles'
origins the physics' own, so a URDF is a planar 2R arm when
- it is one tree with exactly two moving joints (revolute or continuous), the elbow below
  the shoulder, every other joint fixed;
- the shoulder axis a is horizontal and the elbow axis is parallel to it, same direction;
- at zero angles the elbow lies in the shoulder's plane and link 1 points horizontally, and
  a × (link 1's direction) is up: positive angles turn counter-clockwise seen from the side
  a points to, as the physics measures them;
- each link's centre of mass lies on its line (link 2's line is link 1's at zero angles),
  and every other link with mass is fixed to the world.
The physics' x is then link 1's direction at zero angles, its y the world's z, its z the
shoulder axis: a point (x, y) of the physics is the world point shoulder + x·x̂ + y·ẑ. The URDF
that urdf_out.py writes holds that plane as the frame `arm_plane`. Rounding in the URDF's
numbers is allowed up to TOLERANCE (rad, or a fraction of the link's length).

What the URDF decides, in URDF's own terms (an absent element means what URDF says it means):
link lengths (joint origins: l1 shoulder→elbow; l2 elbow→the farthest fixed frame on link 2's
line, the tip, else the base scene's), masses, centres of mass and inertias about the axis
normal to the plane (<inertial>; any other products of inertia are the plane's constraint's
business), <limit lower upper> of revolute joints → joint_limits (a continuous joint beside a
revolute one gets ±MAX_ANGLE, the scene's largest angle), <limit effort> →
effort_limits (a joint without one, or with NO_EFFORT_LIMIT or more, beside a limited one
gets NO_EFFORT_LIMIT), <dynamics damping friction> → viscous damping and
Coulomb friction (absent = 0, as in URDF). <limit velocity> is read, as urdfdom requires it,
but the physics sets no speed limit. Everything else comes from the base scene: gravity, the
initial state, policy, step, the other effects, a hard limit's restitution or a compliant
one's stiffness, static friction and the Stribeck velocity.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from math import asin, degrees

import numpy as np

from ..model import MAX_ANGLE
from ..scene import FIELD_KINDS, Scene, SceneError
from .elements import child_link, element_origin, joint_axis, joint_name, link_mass, read_number

TOLERANCE = 1e-4
# A revolute joint's <limit> needs an effort even where the scene limits none: URDF out writes
# this (N m, beyond any arm's torque; ros2_control takes it literally) and reads it back as no
# limit, as it reads a continuous joint's angle as within ±MAX_ANGLE.
NO_EFFORT_LIMIT = 1e9
MOVING = ("revolute", "continuous")
XACRO = "{http://www.ros.org/wiki/xacro}"
# A robot_description is read whole; these bound the work (the tree is walked in linear time)
MAX_URDF_CHARS = 4_000_000
MAX_LINKS = 1000


@dataclass(frozen=True)
class UrdfArm:
    """What a planar 2R URDF says about the arm, in the physics' terms (per joint/link)."""

    robot: str
    joint_names: tuple[str, str]
    link_lengths: tuple                 # (l1, l2); l2 None when link 2 has no tip frame
    link_masses: tuple[float, float]
    com_distances: tuple[float, float]
    com_inertias: tuple[float, float]
    ranges: tuple                       # (lower, upper) per joint; None = continuous
    effort_limits: tuple | None
    damping: tuple[float, float]
    friction: tuple[float, float]

    def scene(self, base: Scene) -> Scene:
        """`base` with everything this URDF decides replaced (see the module's docstring)."""
        lengths = (self.link_lengths[0], self.link_lengths[1] or base.link_lengths[1])
        changes = dict(link_lengths=lengths, link_masses=self.link_masses,
                       com_distances=self.com_distances, com_inertias=self.com_inertias,
                       damping=self.damping[0] if self.damping[0] == self.damping[1]
                       else self.damping, effort_limits=self.effort_limits,
                       friction=None if self.friction == (0.0, 0.0)
                       else (base.friction or {}) | {"coulomb": self.friction},
                       joint_limits=None)
        if any(self.ranges):
            lower, upper = zip(*(r or (-MAX_ANGLE, MAX_ANGLE)
                                 for r in self.ranges))
            changes["joint_limits"] = (base.joint_limits or {}) | {"lower": lower, "upper": upper}
        try:
            return base.replace(**changes)
        except SceneError as error:
            raise SceneError(f"URDF {self.robot}: {error}") from None


def scene_from_urdf(text: str, base_scene: Scene) -> Scene:
    """The scene `base_scene` with the arm of the URDF `text` (the whole document, as the
    `robot_description` parameter or a .urdf file holds it; a <ros2_control>, <gazebo> or
    <transmission> element in it is ignored).

    The URDF decides the links (lengths, masses, centres of mass, inertias), joint_limits'
    lower and upper, effort_limits, damping and friction; `base_scene` everything else (see
    the module's docstring, which also says how the URDF's frames map onto the physics'
    plane). Joint names are read_urdf(text).joint_names. Pure: nothing is changed.
    Raises SceneError, one line saying why, when `text` is not a planar 2R arm's URDF or its
    values cannot be simulated.
    """
    return read_urdf(text).scene(base_scene)


def read_urdf(text: str) -> UrdfArm:
    """The arm a planar 2R URDF describes; SceneError (one line) saying why it is not one."""
    tree = _Tree(text)
    shoulder, elbow = tree.moving_joints()
    link1, link2 = child_link(shoulder), child_link(elbow)
    tree.check_masses(link1, link2)
    a1 = joint_axis(shoulder)
    rot, e = tree.relative(link1, link2)            # the elbow's frame in link 1's
    a2 = rot @ joint_axis(elbow)
    cosine = float(a1 @ a2)
    if cosine < -(1 - TOLERANCE):
        raise SceneError(f"URDF: the axes of {joint_name(shoulder)} and {joint_name(elbow)} point opposite "
                         "ways, so a positive elbow angle would turn clockwise; reverse one")
    if cosine < 1 - TOLERANCE:
        raise SceneError(f"URDF: the axes of {joint_name(shoulder)} and {joint_name(elbow)} are "
                         f"{degrees(np.arccos(min(1.0, cosine))):.3g}° apart: not parallel, so "
                         "the arm would leave its plane")
    out = float(e @ a1)
    in_plane = e - out * a1
    l1 = float(np.linalg.norm(in_plane))
    if not l1 > 0:
        raise SceneError(f"URDF: {joint_name(elbow)} sits on the axis of {joint_name(shoulder)}: "
                         "link 1 has no length")
    if abs(out) > TOLERANCE * l1:
        raise SceneError(f"URDF: {joint_name(elbow)} is {abs(out):.3g} m out of the plane of "
                         f"{joint_name(shoulder)}: link offsets must lie in the arm's plane")
    d1 = in_plane / l1
    _check_upright(tree.world(link1)[0], a1, d1, shoulder)
    d2 = rot.T @ d1                                 # link 2's line at zero angles, its frame
    tip = tree.tip_length(link2, d2)
    m1, r1, i1 = _body(tree.links[link1], a1, d1, l1)
    m2, r2, i2 = _body(tree.links[link2], joint_axis(elbow), d2, tip or 1.0)
    ranges, efforts = zip(*(_limits(j) for j in (shoulder, elbow)))
    unlimited = [e is None or e >= NO_EFFORT_LIMIT for e in efforts]
    damping, friction = zip(*(_dynamics(j) for j in (shoulder, elbow)))
    return UrdfArm(robot=tree.robot, joint_names=(joint_name(shoulder), joint_name(elbow)),
                   link_lengths=(l1, tip), link_masses=(m1, m2), com_distances=(r1, r2),
                   com_inertias=(i1, i2), ranges=ranges,
                   effort_limits=None if all(unlimited) else tuple(
                       NO_EFFORT_LIMIT if u else e for u, e in zip(unlimited, efforts)),
                   damping=damping, friction=friction)


def _check_upright(rotation, axis, direction, shoulder) -> None:
    """The plane vertical, link 1 horizontal at zero angles, positive angles counter-clockwise
    with the world's z up (see the module's docstring)."""
    a, d = rotation @ axis, rotation @ direction
    if abs(a[2]) > 1 - TOLERANCE:
        raise SceneError(f"URDF: the axis of {joint_name(shoulder)} is vertical, so the arm would "
                         "move in a horizontal plane; the physics' plane is vertical (the "
                         "URDF's z is up, gravity along -z): turn the axes horizontal")
    if abs(a[2]) > TOLERANCE:
        raise SceneError(f"URDF: the axis of {joint_name(shoulder)} is {degrees(asin(a[2])):.3g}° "
                         "off the horizontal: the arm's plane must be vertical (z up)")
    up = float(np.cross(a, d)[2])
    if up < -(1 - TOLERANCE):
        raise SceneError(f"URDF: a positive {joint_name(shoulder)} angle turns link 1 downward "
                         "(clockwise, where the physics turns counter-clockwise): reverse "
                         "both joint axes")
    if up < 1 - TOLERANCE:
        raise SceneError(f"URDF: link 1 points {abs(degrees(asin(d[2]))):.3g}° "
                         f"{'above' if d[2] > 0 else 'below'} the horizontal at zero angles; "
                         "the physics measures q1 from the horizontal")


def _body(link, axis, direction, length):
    """(mass, centre of mass along the link's line, inertia about `axis` at the COM)."""
    name = link.get("name")
    inertial = link.find("inertial")
    mass = link_mass(link)
    if inertial is None or mass is None:
        raise SceneError(f"URDF: link {name} has no <inertial> mass; the physics needs it")
    rotation, com = element_origin(inertial, f"link {name} <inertial>")
    along = float(com @ direction)
    off = float(np.linalg.norm(com - along * direction))
    if off > TOLERANCE * max(length, abs(along)):
        raise SceneError(f"URDF: link {name}'s centre of mass is {off:.3g} m off the link's "
                         "line (joint to joint): the physics' links have it on that line")
    element = inertial.find("inertia")
    if element is None:
        raise SceneError(f"URDF: link {name} has no <inertia>")
    k = {key: read_number(element, key, f"link {name} <inertia>")
         for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
    tensor = np.array([[k["ixx"], k["ixy"], k["ixz"]], [k["ixy"], k["iyy"], k["iyz"]],
                       [k["ixz"], k["iyz"], k["izz"]]])
    return mass, along, float(axis @ (rotation @ tensor @ rotation.T) @ axis)


def _limits(joint):
    """((lower, upper) or None for continuous, effort or None) of a moving joint."""
    limit, where = joint.find("limit"), f"joint {joint_name(joint)} <limit>"
    if limit is None:
        if joint.get("type") == "revolute":
            raise SceneError(f"URDF: revolute joint {joint_name(joint)} has no <limit> (URDF needs "
                             "its lower, upper, effort and velocity)")
        return None, None
    for key in ("effort", "velocity"):      # urdfdom refuses a limit without either
        if limit.get(key) is None:
            raise SceneError(f"URDF: {where} has no {key} (URDF requires it)")
    effort = read_number(limit, "effort", where)
    read_number(limit, "velocity", where)       # checked, not simulated: no speed limit effect
    if joint.get("type") == "continuous":
        return None, effort
    return (read_number(limit, "lower", where, 0.0), read_number(limit, "upper", where, 0.0)), effort


def _dynamics(joint):
    """(viscous damping, Coulomb friction) of a joint; absent = 0, as URDF has it."""
    dynamics = joint.find("dynamics")
    if dynamics is None:
        return 0.0, 0.0
    where = f"joint {joint_name(joint)} <dynamics>"
    return read_number(dynamics, "damping", where, 0.0), read_number(dynamics, "friction", where, 0.0)


class _Tree:
    """The URDF's links and joints as a tree from its root link."""

    def __init__(self, text: str):
        if not isinstance(text, str) or not text.strip():
            raise SceneError("URDF: empty robot description")
        if len(text) > MAX_URDF_CHARS:
            raise SceneError(f"URDF: {len(text)} characters; a planar 2R arm's description "
                             f"fits in {MAX_URDF_CHARS} (meshes are referenced, not inlined)")
        try:
            root = ET.fromstring(text)
        except ET.ParseError as error:
            raise SceneError(f"URDF: not well-formed XML ({error})") from None
        if root.tag != "robot":
            raise SceneError(f"URDF: the document's root element is <{root.tag}>, not <robot>")
        if any(e.tag.startswith(XACRO) for e in root.iter()) or "${" in text:
            raise SceneError("URDF: this is a xacro file; expand it first "
                             "(xacro FILE > FILE.urdf)")
        self.robot = root.get("name") or "robot"
        self.links = {}
        for link in root.findall("link"):
            name = link.get("name")
            if not name or name in self.links:
                raise SceneError(f"URDF: a <link> is {'unnamed' if not name else 'named twice: ' + name}")
            self.links[name] = link
        if len(self.links) > MAX_LINKS:
            raise SceneError(f"URDF: {len(self.links)} links; a planar 2R arm has two moving "
                             f"ones and at most {MAX_LINKS} in all")
        self.parent_joint = {}                       # child link -> its joint
        for joint in root.findall("joint"):
            parent, child = (joint.find(k).get("link") if joint.find(k) is not None else None
                             for k in ("parent", "child"))
            for end in (parent, child):
                if end not in self.links:
                    raise SceneError(f"URDF: joint {joint_name(joint)} names link {end!r}, which "
                                     "the URDF does not have")
            if child in self.parent_joint:
                raise SceneError(f"URDF: link {child} is the child of two joints")
            self.parent_joint[child] = joint
        roots = [name for name in self.links if name not in self.parent_joint]
        if len(roots) != 1:
            raise SceneError(f"URDF: {len(roots)} root links ({', '.join(roots) or 'a loop'}); "
                             "a robot is one tree")
        self.root = roots[0]
        self.children = {}                           # parent link -> its joints
        for joint in self.parent_joint.values():
            self.children.setdefault(joint.find("parent").get("link"), []).append(joint)
        self.order = self.below(self.root)            # every link once, parents first
        if len(self.order) != len(self.links):        # what the root does not reach is a loop
            stray = next(name for name in self.links if name not in set(self.order))
            raise SceneError(f"URDF: the joints around link {stray} form a loop")

    def below(self, top) -> list:
        """`top` and every link below it, each after its parent: one pass, linear in links."""
        order, stack = [], [top]
        while stack:
            link = stack.pop()
            order.append(link)
            stack += [child_link(joint) for joint in self.children.get(link, ())]
        return order

    def chain(self, link) -> list:
        """The joints from the root to `link`, root first."""
        joints, seen = [], {link}
        while link in self.parent_joint:
            joint = self.parent_joint[link]
            joints.append(joint)
            link = joint.find("parent").get("link")
            if link in seen:
                raise SceneError(f"URDF: the joints around link {link} form a loop")
            seen.add(link)
        return joints[::-1]

    def moving_joints(self):
        """(shoulder, elbow): the two moving joints, the elbow below the shoulder."""
        moving = []
        for joint in self.parent_joint.values():
            kind = joint.get("type")
            if kind in MOVING:
                moving.append(joint)
            elif kind != "fixed":
                raise SceneError(f"URDF: joint {joint_name(joint)} is {kind}: a planar 2R arm has "
                                 "two revolute or continuous joints, and fixed ones")
        if len(moving) != 2:
            raise SceneError(f"URDF: {len(moving)} revolute or continuous joints "
                             f"({', '.join(map(joint_name, moving)) or 'none'}); a 2R arm has two")
        for shoulder, elbow in (moving, moving[::-1]):
            if any(j is shoulder for j in self.chain(child_link(elbow))):
                return shoulder, elbow
        raise SceneError(f"URDF: {joint_name(moving[0])} and {joint_name(moving[1])} are on separate "
                         "branches, not one chain")

    def check_masses(self, link1, link2) -> None:
        """Only the two links move with mass: a massive link fixed to one is refused."""
        carried = {self.root: None}    # link -> the moving link it is fixed to (None: base)
        for name in self.order[1:]:
            joint = self.parent_joint[name]
            carried[name] = (name if joint.get("type") in MOVING
                             else carried[joint.find("parent").get("link")])
        for name, link in self.links.items():
            if name in (link1, link2) or not link_mass(link):
                continue
            if carried[name] is not None:
                body = carried[name]
                raise SceneError(f"URDF: link {name} ({link_mass(link):g} kg) is fixed to {body}: "
                                 f"fold it into {body}'s <inertial> (the physics has two "
                                 "rigid links)")

    def relative(self, ancestor, link):
        """(rotation, translation) of `link`'s frame in `ancestor`'s, at zero angles."""
        rotation, translation = np.eye(3), np.zeros(3)
        for joint in self.chain(link)[len(self.chain(ancestor)):]:
            r, t = element_origin(joint, f"joint {joint_name(joint)}")
            rotation, translation = rotation @ r, translation + rotation @ t
        return rotation, translation

    def world(self, link):
        return self.relative(self.root, link)

    def tip_length(self, link2, direction):
        """How far the farthest frame fixed to link 2 on its line is from the elbow."""
        best, frames = None, {link2: (np.eye(3), np.zeros(3))}
        for name in self.below(link2)[1:]:           # link 2's frame carried down, once each
            joint = self.parent_joint[name]
            rotation, translation = frames[joint.find("parent").get("link")]
            r, t = element_origin(joint, f"joint {joint_name(joint)}")
            frames[name] = (rotation @ r, translation + rotation @ t)
            t = frames[name][1]
            along = float(t @ direction)
            if along > 0 and np.linalg.norm(t - along * direction) <= TOLERANCE * along:
                best = along if best is None else max(best, along)
        return best


def changed_values(scene: "Scene", other: "Scene") -> list[str]:
    """`key old -> new` for every value `other` changed (a table shown by its keys only), e.g.
    what a URDF replaced."""
    def shown(value):
        if isinstance(value, tuple):
            return "(" + ", ".join(f"{v:g}" for v in value) + ")"
        if isinstance(value, dict):
            return "{" + ", ".join(value) + "}"
        return "none" if value is None else f"{value:g}" if isinstance(value, float) else str(value)
    return [f"{key} {shown(getattr(scene, key))} -> {shown(getattr(other, key))}"
            for key in FIELD_KINDS if key != "name" and getattr(scene, key) != getattr(other, key)]
