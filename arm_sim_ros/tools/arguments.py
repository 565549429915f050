"""What every `arm-sim` subcommand shares: choosing a scene from the command line."""
from __future__ import annotations

from ..physics.scene import Scene, load_scene, parse_value


def scene_from_args(args) -> Scene:
    """The scene named by --scene, with --step and --set applied (shared by subcommands)."""
    scene = load_scene(args.scene)
    if getattr(args, "step", None) is not None:
        scene = scene.replace(step_size=parse_value("step_size", args.step))
    return scene.with_text_overrides(getattr(args, "set", None) or [])


def add_scene_arguments(parser) -> None:
    parser.add_argument("--scene", default="release", help="preset name (see `arm-sim scenes`) or a scene .yaml file")
    parser.add_argument("--step", help="RK step size h in seconds (default: the scene's)")
    parser.add_argument("--set", action="append", metavar="KEY=VALUE",
                        help="override a scene key, e.g. gravity=0, constant_torque=1,0 or "
                             "springs.stiffness=20,5")
