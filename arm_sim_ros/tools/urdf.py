"""`arm-sim urdf`: the URDF of a scene's arm (physics/urdf/write.py), on stdout or to a file.

    arm-sim urdf                                  # the default scene: urdf/two_link_arm.urdf
    arm-sim urdf --scene limit_impact -o arm.urdf
    arm-sim urdf --set link_lengths=0.8,1.2 --set effort_limits=30,10
"""
from __future__ import annotations

import sys

from ..outputs import check_output, write_text
from ..physics.urdf.write import scene_to_urdf
from .arguments import add_scene_arguments, scene_from_args


def cmd_urdf(args) -> int:
    text = scene_to_urdf(scene_from_args(args), robot=args.robot)
    if args.output is None:
        sys.stdout.write(text)
        return 0
    write_text(check_output(args.output, "-o", args.force), text, "-o")
    return 0


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("urdf", help="print the URDF of a scene's arm (for "
                                           "robot_state_publisher and RViz)")
    add_scene_arguments(p, stepping=False)      # the arm only: no step, no tolerance
    p.add_argument("-o", "--output", metavar="PATH", help="write the URDF to PATH")
    p.add_argument("--force", action="store_true", help="replace an existing -o file")
    p.add_argument("--robot", default="two_link_arm", help="the <robot> name")
    p.set_defaults(func=cmd_urdf)
