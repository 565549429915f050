"""The arm in 3D from the shipped URDF (urdf/two_link_arm.urdf): its links logged once by
Rerun's URDF loader, its two joints turned by the simulated angles, each link's centre of
mass, the joint torques as arrows along the joint axes and the gravity vector.

The URDF's frames are the physics' (x right, y up, z out of the plane; both joints about
+z), so nothing is flipped here. The URDF holds the default arm (1 m rods, COMs at 0.5 m):
a scene whose links differ gets no 3D view rather than a wrong one. The joints and arrows
are sent at the 2D drawing's frames (writer.FRAME_PERIOD), from the sender thread.
"""
from __future__ import annotations

import os
import sys
from functools import lru_cache
from pathlib import Path

import numpy as np
import rerun as rr

from .columns import joint_transforms, vectors3d

ROOT = "arm3d"
URDF_NAME = "two_link_arm.urdf"
JOINTS = ("shoulder_joint", "elbow_joint")
LINKS = ("link1", "link2")               # the frame each joint turns, in URDF order
TORQUE_SCALE = 0.05                      # m of arrow per N m of joint torque
GRAVITY_SCALE = 0.05                     # m of arrow per m/s² of gravity
TORQUE_PATHS = tuple(f"{ROOT}/torque/{joint}" for joint in JOINTS)
COLORS = ((80, 220, 235), (255, 205, 70))   # as the 2D joints: shoulder cyan, elbow amber


def urdf_path() -> Path | None:
    """The shipped URDF: $ARM_SIM_URDF, the source tree, or where pip or colcon install it."""
    candidates = [Path(os.environ["ARM_SIM_URDF"])] if os.environ.get("ARM_SIM_URDF") else []
    candidates += [Path(__file__).resolve().parents[2] / "urdf" / URDF_NAME,
                   Path(sys.prefix) / "share" / "arm_sim_ros" / "urdf" / URDF_NAME]
    try:  # a colcon install puts it in the package's share directory
        from ament_index_python.packages import get_package_share_directory
        candidates.append(Path(get_package_share_directory("arm_sim_ros")) / "urdf" / URDF_NAME)
    except Exception:
        pass
    return next((p for p in candidates if p.is_file()), None)


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
            made = cls(path)
        except Exception:     # an unreadable URDF: no 3D view, the recording goes on
            return None
        lengths = (made.joints[1].origin_xyz[0], made.tree.get_joint_by_name("tip_joint")
                   .origin_xyz[0])
        same = np.allclose(lengths, arm.link_lengths, rtol=0, atol=1e-9) and all(
            tuple(j.axis) == (0.0, 0.0, 1.0) and not any(j.origin_rpy) for j in made.joints)
        return made if same and np.allclose(arm.com_distances, (0.5 * lengths[0],
                                                                0.5 * lengths[1])) else None

    def log_static(self, stream, arm, gravity: float, torques: bool) -> None:
        """The links (Rerun's URDF loader), the COMs in their links' frames, the gravity
        vector at the base, and the torque arrows' frames and colours."""
        stream.log_file_from_path(self.path, entity_path_prefix=ROOT, static=True)
        stream.log(ROOT, rr.ViewCoordinates.RIGHT_HAND_Y_UP, static=True)   # as the URDF's frames
        for link, distance, mass in zip(LINKS, arm.com_distances, arm.link_masses):
            stream.log(f"{ROOT}/com/{link}", rr.CoordinateFrame(link),
                       rr.Points3D([(distance, 0.0, 0.0)], radii=[0.035], colors=[(245, 245, 245)],
                                   labels=[f"COM {mass:g} kg"], show_labels=False), static=True)
        if gravity:
            stream.log(f"{ROOT}/gravity", rr.CoordinateFrame("base_link"), rr.Arrows3D(
                origins=[(-0.5 * sum(arm.link_lengths), 0.0, 0.0)],
                vectors=[(0.0, -GRAVITY_SCALE * gravity, 0.0)], colors=[(100, 150, 255)],
                labels=[f"g {gravity:g} m/s²"], radii=[0.015]), static=True)
        if torques:
            for path, link, color in zip(TORQUE_PATHS, LINKS, COLORS):
                stream.log(path, rr.CoordinateFrame(link), rr.Arrows3D.from_fields(
                    colors=[color], radii=[0.02]), static=True)

    def send(self, stream, index, q1, q2, torque=None) -> None:
        """The joints at angles q1, q2 (a turn about +z: the URDF's axes, checked in
        for_arm) and, with a drive, the (n, 2) joint torques as arrows along +z, on the time
        columns `index`. Built as Arrow: UrdfJoint.compute_transform_columns costs 1.5 µs
        a step through Python lists."""
        for joint, angles in zip(self.joints, (q1, q2)):
            half = 0.5 * np.asarray(angles, dtype=float)
            xyzw = np.zeros((len(half), 4))
            xyzw[:, 2], xyzw[:, 3] = np.sin(half), np.cos(half)
            rr.send_columns(f"{ROOT}/joints/{joint.name}", indexes=index,
                            columns=joint_transforms(xyzw, joint.origin_xyz, joint.parent_link,
                                                     joint.child_link), recording=stream)
        if torque is None:
            return
        for k, path in enumerate(TORQUE_PATHS):
            arrows = np.zeros((len(torque), 3))
            arrows[:, 2] = TORQUE_SCALE * torque[:, k]
            rr.send_columns(path, indexes=index, columns=vectors3d(arrows), recording=stream)


@lru_cache(maxsize=8)
def arm3d_for(arm) -> Arm3D | None:
    """Arm3D.for_arm, read once per arm (model.ArmParameters is hashable)."""
    return Arm3D.for_arm(arm)
