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
revolute one gets ±MAX_INITIAL_ANGLE, the scene's largest angle), <limit effort> →
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
from math import asin, degrees, isfinite, sqrt

import numpy as np

from .scene import MAX_INITIAL_ANGLE, Scene, SceneError

TOLERANCE = 1e-4
# A revolute joint's <limit> needs an effort even where the scene limits none: URDF out writes
# this (N m, beyond any arm's torque; ros2_control takes it literally) and reads it back as no
# limit, as it reads a continuous joint's angle as within ±MAX_INITIAL_ANGLE.
NO_EFFORT_LIMIT = 1e9
MOVING = ("revolute", "continuous")
XACRO = "{http://www.ros.org/wiki/xacro}"


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
            lower, upper = zip(*(r or (-MAX_INITIAL_ANGLE, MAX_INITIAL_ANGLE)
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
    link1, link2 = _child(shoulder), _child(elbow)
    tree.check_masses(link1, link2)
    a1 = _axis(shoulder)
    rot, e = tree.relative(link1, link2)            # the elbow's frame in link 1's
    a2 = rot @ _axis(elbow)
    cosine = float(a1 @ a2)
    if cosine < -(1 - TOLERANCE):
        raise SceneError(f"URDF: the axes of {_name(shoulder)} and {_name(elbow)} point opposite "
                         "ways, so a positive elbow angle would turn clockwise; reverse one")
    if cosine < 1 - TOLERANCE:
        raise SceneError(f"URDF: the axes of {_name(shoulder)} and {_name(elbow)} are "
                         f"{degrees(np.arccos(min(1.0, cosine))):.3g}° apart: not parallel, so "
                         "the arm would leave its plane")
    out = float(e @ a1)
    in_plane = e - out * a1
    l1 = float(np.linalg.norm(in_plane))
    if not l1 > 0:
        raise SceneError(f"URDF: {_name(elbow)} sits on the axis of {_name(shoulder)}: "
                         "link 1 has no length")
    if abs(out) > TOLERANCE * l1:
        raise SceneError(f"URDF: {_name(elbow)} is {abs(out):.3g} m out of the plane of "
                         f"{_name(shoulder)}: link offsets must lie in the arm's plane")
    d1 = in_plane / l1
    _check_upright(tree.world(link1)[0], a1, d1, shoulder)
    d2 = rot.T @ d1                                 # link 2's line at zero angles, its frame
    tip = tree.tip_length(link2, d2)
    m1, r1, i1 = _body(tree.links[link1], a1, d1, l1)
    m2, r2, i2 = _body(tree.links[link2], _axis(elbow), d2, tip or 1.0)
    ranges, efforts = zip(*(_limits(j) for j in (shoulder, elbow)))
    unlimited = [e is None or e >= NO_EFFORT_LIMIT for e in efforts]
    damping, friction = zip(*(_dynamics(j) for j in (shoulder, elbow)))
    return UrdfArm(robot=tree.robot, joint_names=(_name(shoulder), _name(elbow)),
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
        raise SceneError(f"URDF: the axis of {_name(shoulder)} is vertical, so the arm would "
                         "move in a horizontal plane; the physics' plane is vertical (the "
                         "URDF's z is up, gravity along -z): turn the axes horizontal")
    if abs(a[2]) > TOLERANCE:
        raise SceneError(f"URDF: the axis of {_name(shoulder)} is {degrees(asin(a[2])):.3g}° "
                         "off the horizontal: the arm's plane must be vertical (z up)")
    up = float(np.cross(a, d)[2])
    if up < -(1 - TOLERANCE):
        raise SceneError(f"URDF: a positive {_name(shoulder)} angle turns link 1 downward "
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
    mass = _mass(link)
    if inertial is None or mass is None:
        raise SceneError(f"URDF: link {name} has no <inertial> mass; the physics needs it")
    rotation, com = _origin(inertial, f"link {name} <inertial>")
    along = float(com @ direction)
    off = float(np.linalg.norm(com - along * direction))
    if off > TOLERANCE * max(length, abs(along)):
        raise SceneError(f"URDF: link {name}'s centre of mass is {off:.3g} m off the link's "
                         "line (joint to joint): the physics' links have it on that line")
    element = inertial.find("inertia")
    if element is None:
        raise SceneError(f"URDF: link {name} has no <inertia>")
    k = {key: _number(element, key, f"link {name} <inertia>")
         for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
    tensor = np.array([[k["ixx"], k["ixy"], k["ixz"]], [k["ixy"], k["iyy"], k["iyz"]],
                       [k["ixz"], k["iyz"], k["izz"]]])
    return mass, along, float(axis @ (rotation @ tensor @ rotation.T) @ axis)


def _limits(joint):
    """((lower, upper) or None for continuous, effort or None) of a moving joint."""
    limit, where = joint.find("limit"), f"joint {_name(joint)} <limit>"
    if limit is None:
        if joint.get("type") == "revolute":
            raise SceneError(f"URDF: revolute joint {_name(joint)} has no <limit> (URDF needs "
                             "its lower, upper, effort and velocity)")
        return None, None
    for key in ("effort", "velocity"):      # urdfdom refuses a limit without either
        if limit.get(key) is None:
            raise SceneError(f"URDF: {where} has no {key} (URDF requires it)")
    effort = _number(limit, "effort", where)
    _number(limit, "velocity", where)       # checked, not simulated: no speed limit effect
    if joint.get("type") == "continuous":
        return None, effort
    return (_number(limit, "lower", where, 0.0), _number(limit, "upper", where, 0.0)), effort


def _dynamics(joint):
    """(viscous damping, Coulomb friction) of a joint; absent = 0, as URDF has it."""
    dynamics = joint.find("dynamics")
    if dynamics is None:
        return 0.0, 0.0
    where = f"joint {_name(joint)} <dynamics>"
    return _number(dynamics, "damping", where, 0.0), _number(dynamics, "friction", where, 0.0)


class _Tree:
    """The URDF's links and joints as a tree from its root link."""

    def __init__(self, text: str):
        if not isinstance(text, str) or not text.strip():
            raise SceneError("URDF: empty robot description")
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
        self.parent_joint = {}                       # child link -> its joint
        for joint in root.findall("joint"):
            parent, child = (joint.find(k).get("link") if joint.find(k) is not None else None
                             for k in ("parent", "child"))
            for end in (parent, child):
                if end not in self.links:
                    raise SceneError(f"URDF: joint {_name(joint)} names link {end!r}, which "
                                     "the URDF does not have")
            if child in self.parent_joint:
                raise SceneError(f"URDF: link {child} is the child of two joints")
            self.parent_joint[child] = joint
        roots = [name for name in self.links if name not in self.parent_joint]
        if len(roots) != 1:
            raise SceneError(f"URDF: {len(roots)} root links ({', '.join(roots) or 'a loop'}); "
                             "a robot is one tree")
        self.root = roots[0]
        for link in self.links:
            self.chain(link)                          # refuses a loop

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
                raise SceneError(f"URDF: joint {_name(joint)} is {kind}: a planar 2R arm has "
                                 "two revolute or continuous joints, and fixed ones")
        if len(moving) != 2:
            raise SceneError(f"URDF: {len(moving)} revolute or continuous joints "
                             f"({', '.join(map(_name, moving)) or 'none'}); a 2R arm has two")
        for shoulder, elbow in (moving, moving[::-1]):
            if any(j is shoulder for j in self.chain(_child(elbow))):
                return shoulder, elbow
        raise SceneError(f"URDF: {_name(moving[0])} and {_name(moving[1])} are on separate "
                         "branches, not one chain")

    def check_masses(self, link1, link2) -> None:
        """Only the two links move with mass: a massive link fixed to one is refused."""
        for name, link in self.links.items():
            if name in (link1, link2) or not _mass(link):
                continue
            moving = [j for j in self.chain(name) if j.get("type") in MOVING]
            if moving:
                body = _child(moving[-1])
                raise SceneError(f"URDF: link {name} ({_mass(link):g} kg) is fixed to {body}: "
                                 f"fold it into {body}'s <inertial> (the physics has two "
                                 "rigid links)")

    def relative(self, ancestor, link):
        """(rotation, translation) of `link`'s frame in `ancestor`'s, at zero angles."""
        rotation, translation = np.eye(3), np.zeros(3)
        for joint in self.chain(link)[len(self.chain(ancestor)):]:
            r, t = _origin(joint, f"joint {_name(joint)}")
            rotation, translation = rotation @ r, translation + rotation @ t
        return rotation, translation

    def world(self, link):
        return self.relative(self.root, link)

    def tip_length(self, link2, direction):
        """How far the farthest frame fixed to link 2 on its line is from the elbow."""
        best = None
        for name in self.links:
            chain = self.chain(name)
            if name == link2 or not any(_child(j) == link2 for j in chain):
                continue
            t = self.relative(link2, name)[1]
            along = float(t @ direction)
            if along > 0 and np.linalg.norm(t - along * direction) <= TOLERANCE * along:
                best = along if best is None else max(best, along)
        return best


def _name(joint) -> str:
    return joint.get("name") or "(unnamed joint)"


def _child(joint) -> str:
    return joint.find("child").get("link")


def _mass(link):
    element = link.find("inertial/mass")
    return None if element is None else _number(element, "value", f"link {link.get('name')} <mass>")


def _number(element, key, where, default=None) -> float:
    text = element.get(key)
    if text is None:
        if default is None:
            raise SceneError(f"URDF: {where} has no {key}")
        return default
    try:
        value = float(text)
    except ValueError:
        raise SceneError(f"URDF: {where} {key}={text!r} is not a number") from None
    if not isfinite(value):
        raise SceneError(f"URDF: {where} {key}={text!r} is not finite")
    return value


def _vector(element, key, where, default) -> np.ndarray:
    text = element.get(key) if element is not None else None
    if text is None:
        return np.array(default, dtype=float)
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) != 3 or not all(isfinite(v) for v in values):
        raise SceneError(f"URDF: {where} {key}={text!r} is not three finite numbers")
    return np.array(values)


def _origin(element, where):
    """(rotation, translation) of an element's <origin>: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    origin = element.find("origin")
    xyz = _vector(origin, "xyz", where + " <origin>", (0.0, 0.0, 0.0))
    roll, pitch, yaw = _vector(origin, "rpy", where + " <origin>", (0.0, 0.0, 0.0))
    return _rotation(roll, pitch, yaw), xyz


def _rotation(roll, pitch, yaw) -> np.ndarray:
    if not (roll or pitch or yaw):
        return np.eye(3)                   # exact: generated URDFs read back bit for bit
    cr, sr, cp, sp, cy, sy = (np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch),
                              np.cos(yaw), np.sin(yaw))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _axis(joint) -> np.ndarray:
    """The joint's unit axis in its child's frame (URDF's default: x)."""
    axis = _vector(joint.find("axis"), "xyz", f"joint {_name(joint)} <axis>", (1.0, 0.0, 0.0))
    norm = sqrt(float(axis @ axis))
    if not norm > 0:
        raise SceneError(f"URDF: joint {_name(joint)} has a zero <axis>")
    return axis / norm
