"""The arm in 3D from the shipped URDF (urdf/two_link_arm.urdf): its links logged once by
Rerun's URDF loader, its two joints turned by the simulated angles, each link's centre of
mass, the joint torques as arrows along the joint axes and the gravity vector.

The URDF's root is the world, z up as in RViz (physics/urdf/read.py says how its frames map onto
the physics' plane): the view is z up, the arm's plane vertical, gravity pointing down. The
URDF holds the default arm (1 m rods, COMs at 0.5 m): a scene whose links differ gets no 3D
view rather than a wrong one. A payload is no link: the scene's bare links are compared (the
COMs drawn are those the physics moves, payload folded in). The joints and arrows are sent
at the 2D drawing's frames (writer.FRAME_PERIOD), from the sender thread.
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import rerun as rr

from ...interface import JOINT_NAMES as JOINTS
from ...physics.scene import scene_dirs
from ...physics.urdf.read import read_urdf
from .blueprint import JOINT_COLORS
from .columns import joint_transforms, vectors3d
from ..readouts import FLOAT32_MAX

ROOT = "arm3d"
URDF_NAME = "two_link_arm.urdf"
LINKS = ("link1", "link2")               # the frame each joint turns, in URDF order
PLANE = "arm_plane"                      # the URDF's frame of the physics' plane (y up)
TORQUE_SCALE = 0.05                      # m of arrow per N m of joint torque
GRAVITY_SCALE = 0.05                     # m of arrow per m/s² of gravity
TORQUE_PATHS = tuple(f"{ROOT}/torque/{joint}" for joint in JOINTS)


def urdf_path() -> Path | None:
    """The shipped URDF, urdf/ beside config/scenes wherever the presets are found
    (physics.scene.scene_dirs: the source tree, or where pip or colcon install them)."""
    found = (scenes.parents[1] / "urdf" / URDF_NAME for scenes in scene_dirs())
    return next((p for p in found if p.is_file()), None)


class Arm3D:
    """The 3D arm of one recording: log_static() once, send() at each batch's frames."""

    def __init__(self, path: Path):
        self.path = path
        self.tree = rr.urdf.UrdfTree.from_file_path(path)
        self.joints = [self.tree.get_joint_by_name(name) for name in JOINTS]

    @classmethod
    def for_arm(cls, arm) -> "Arm3D | None":
        """The URDF's arm if it is `arm` (link lengths and COMs), else None."""
        path = urdf_path()
        if path is None:
            return None
        try:
            made, read = cls(path), read_urdf(path.read_text(encoding="utf-8"))
        except Exception:     # unreadable (Rerun's loader or ours): no 3D view, the recording goes on
            return None
        same = (read.link_lengths[1] is not None
                and np.allclose(read.link_lengths, arm.link_lengths, rtol=0, atol=1e-9)
                and np.allclose(read.com_distances, arm.com_distances, rtol=0, atol=1e-9))
        return made if same else None

    def log_static(self, stream, arm, gravity: float, torques: bool) -> None:
        """The links (Rerun's URDF loader), the COMs in their links' frames, the gravity
        vector at the base, and the torque arrows' frames and colours."""
        stream.log_file_from_path(self.path, entity_path_prefix=ROOT, static=True)
        stream.log(ROOT, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)   # as the URDF's root
        for link, distance, mass in zip(LINKS, arm.com_distances, arm.link_masses):
            stream.log(f"{ROOT}/com/{link}", rr.CoordinateFrame(link),
                       rr.Points3D([(distance, 0.0, 0.0)], radii=[0.035], colors=[(245, 245, 245)],
                                   labels=[f"COM {mass:g} kg"], show_labels=False), static=True)
        if gravity:   # along the plane's -y: the world's -z; never longer than the arm reaches
            reach = sum(arm.link_lengths)
            stream.log(f"{ROOT}/gravity", rr.CoordinateFrame(PLANE), rr.Arrows3D(
                origins=[(-0.5 * reach, 0.0, 0.0)],
                vectors=[(0.0, -max(-reach, min(reach, GRAVITY_SCALE * gravity)), 0.0)],
                colors=[(100, 150, 255)],
                labels=[f"g {gravity:g} m/s²"], radii=[0.015]), static=True)
        if torques:
            for path, link, color in zip(TORQUE_PATHS, LINKS, JOINT_COLORS):
                stream.log(path, rr.CoordinateFrame(link), rr.Arrows3D.from_fields(
                    colors=[color], radii=[0.02]), static=True)

    def send(self, send, index, q1, q2, torque=None) -> None:
        """The joints at angles q1, q2 (each a turn about its axis after its origin's
        rotation) and, with a drive, the (n, 2) joint torques as arrows along the joint axes,
        on the time columns `index`, each through `send(path, index, build, data, *options)`
        (writer.BatchWriter._send_columns). Built as Arrow: UrdfJoint.compute_transform_columns
        costs 1.5 µs a step through Python lists."""
        for joint, angles in zip(self.joints, (q1, q2)):
            half = 0.5 * np.asarray(angles, dtype=float)
            turn = np.zeros((len(half), 4))
            turn[:, :3], turn[:, 3] = np.outer(np.sin(half), joint.axis), np.cos(half)
            send(f"{ROOT}/joints/{joint.name}", index, joint_transforms,
                 compose(rpy_quaternion(joint.origin_rpy), turn), tuple(joint.origin_xyz),
                 joint.parent_link, joint.child_link)
        shown = None if torque is None else np.all(
            np.abs(TORQUE_SCALE * torque) < FLOAT32_MAX, axis=1)     # the viewer's float32
        if shown is None or not shown.any():
            return
        index = tuple(column[shown] for column in index)
        for k, (path, joint) in enumerate(zip(TORQUE_PATHS, self.joints)):
            arrows = TORQUE_SCALE * np.outer(torque[shown, k], joint.axis)
            send(path, index, vectors3d, arrows)


def rpy_quaternion(rpy) -> np.ndarray:
    """URDF's roll-pitch-yaw (fixed x, y, z axes) as a quaternion (x, y, z, w)."""
    (cr, cp, cy), (sr, sp, sy) = np.cos(0.5 * np.asarray(rpy)), np.sin(0.5 * np.asarray(rpy))
    return np.array([sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy])


def compose(first, then) -> np.ndarray:
    """Hamilton products first ⊗ then[i] of quaternions (x, y, z, w): `then` in `first`'s frame."""
    (x1, y1, z1, w1), (x2, y2, z2, w2) = first, then.T
    return np.stack([w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2],
                    axis=1)


@lru_cache(maxsize=8)
def arm3d_for(arm) -> Arm3D | None:
    """Arm3D.for_arm, read once per arm (model.ArmParameters is hashable)."""
    return Arm3D.for_arm(arm)
