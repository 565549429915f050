"""What every `arm-sim` subcommand shares: choosing a scene from the command line."""
from __future__ import annotations

import sys
from dataclasses import replace as dataclass_replace
from pathlib import Path

from ..physics.model import angle_warning
from ..physics.scene import Scene, SceneError, load_scene, parse_value
from ..physics.urdf.read import changed_values, read_urdf


def scene_from_args(args, note=None) -> Scene:
    """The scene named by --scene, the arm of --urdf on it, then --step and --set applied
    (shared by subcommands). `note` (default: stderr) hears one line naming what --urdf
    replaced and one warning when an initial angle looks like degrees."""
    note = note or (lambda line: print(f"arm-sim: {line}", file=sys.stderr))
    scene = load_scene(args.scene)
    if getattr(args, "urdf", None) is not None:
        robot = read_urdf(read_urdf_file(args.urdf))
        on_urdf = robot.scene(scene)
        note(urdf_replacements(args.urdf, scene, on_urdf))
        # the header and the recording then say whose arm this is
        scene = dataclass_replace(on_urdf, name=f"{scene.name} on {Path(args.urdf).name}")
    if getattr(args, "step", None) is not None:
        scene = scene.replace(step_size=parse_value("step_size", args.step))
    options = {key: parse_value(key, getattr(args, key)) for key in ("tolerance", "max_substeps")
               if getattr(args, key, None) is not None}
    if getattr(args, "estimate", None) is not None:   # off alone: tolerance 0 (Scene.replace)
        options["estimate"] = args.estimate
    # the options and --set in one change: `--set estimate=off --tolerance 1e-3` is refused
    # as `--estimate off --tolerance 1e-3` is, not the tolerance dropped
    scene = scene.with_text_overrides(getattr(args, "set", None) or [], options)
    warning = angle_warning(scene.initial_positions)
    if warning:
        note(f"warning: {warning}")
    return scene


def urdf_replacements(path: str, scene: Scene, on_urdf: Scene) -> str:
    """One line: every scene value the URDF replaced, old -> new (a table by its key only)."""
    changed = changed_values(scene, on_urdf)
    if not changed:
        return f"--urdf {path}: the arm of scene {scene.name} already; nothing replaced"
    return f"--urdf {path} replaced in scene {scene.name}: {'; '.join(changed)}"


def read_urdf_file(path: str) -> str:
    """The text of the --urdf file, or SceneError (one line) saying why it cannot be read."""
    try:
        return Path(path).read_text(encoding="utf-8")
    except (OSError, ValueError) as error:        # missing, a directory, not UTF-8
        reason = getattr(error, "strerror", None) or error
        raise SceneError(f"--urdf {path}: cannot read it ({reason})") from None


def add_scene_arguments(parser, stepping: bool = True, scene_option: bool = True) -> None:
    """--scene (unless the command takes the scene as its first argument), --urdf and --set;
    with `stepping` (a command that integrates) --step, --tolerance and --max-substeps too."""
    if scene_option:
        parser.add_argument("--scene", default="release",
                            help="preset name (see `arm-sim scenes`) or a scene .yaml file")
    parser.add_argument("--urdf", metavar="FILE",
                        help="take the arm from a planar 2R URDF: links, inertias, joint and "
                             "effort limits, damping, friction; the scene gives the rest")
    if stepping:
        add_stepping_arguments(parser)
    parser.add_argument("--set", action="append", metavar="KEY=VALUE",
                        help="override a scene key, e.g. gravity=0, constant_torque=1,0 or "
                             "springs.stiffness=20,5; an angle (a key in rad) may be written "
                             "in degrees, 90deg")


def add_stepping_arguments(parser) -> None:
    parser.add_argument("--step", help="RK step size h in seconds (default: the scene's)")
    parser.add_argument("--tolerance", metavar="TOL",
                        help="local error per simulated second a step may make before it is "
                             "split into sub-steps (0 = estimate only; default: the scene's)")
    parser.add_argument("--max-substeps", dest="max_substeps", metavar="N",
                        help="the most sub-steps the tolerance may ask of one step "
                             "(default: the scene's, 1000)")
