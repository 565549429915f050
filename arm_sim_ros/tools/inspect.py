"""`arm-sim inspect REC.rrd`: what a Rerun recording of this package holds, as text;
`arm-sim inspect --source SCENE`: the module a scene compiles to.

First the recording's properties (the scene, integrator, effects, clock and units the
recorder stored), one `# property.key = value` line each; then its scalar series as CSV on
simulated time: sim_time [s], ros_time and log_time [ns since the epoch], then one column
per series component, headed `entity:series name [unit]`. Cells a series has no value for
(the node's per-tick story between ticks) are empty. `--every N` keeps every Nth row;
`--properties` prints only the properties, `--no-properties` only the table.

The compiled path's code is generated (physics/compiled/build.py): `--source SCENE` prints
the module a scene's steps and runs compile to, as written to the kernel cache, headed by
its file name and what runs it. A switching scene's modes each compile a module of the same
form with that mode's right-hand side, when first met.
"""
from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

from ..usage import UsageError


def _text(value) -> str:
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, list):
        return json.dumps(value, ensure_ascii=False)
    return str(value)


def property_lines(props: dict) -> list[str]:
    return [f"# {name}.{key} = {_text(value)}"
            for name, values in props.items() for key, value in values.items()]


def cmd_inspect(args) -> int:
    if args.source is not None:
        if args.recording is not None:
            raise UsageError("give a recording (REC.rrd) or --source SCENE, not both")
        print(scene_source(args.source), end="")
        return 0
    if args.recording is None:
        raise UsageError("inspect needs a recording (REC.rrd), or --source SCENE for the "
                         "module a scene compiles to")
    from ..recording.rrd.readback import RecordingError, read, table  # rerun: only here

    path = Path(args.recording)
    if not path.is_file():
        raise UsageError(not_a_recording(path, args.recording))
    if args.every < 1:
        raise UsageError(f"--every {args.every} must be at least 1")
    try:
        recording = read(path)
        if not args.no_properties:
            print("\n".join(property_lines(recording[0])))
        if args.properties:
            return 0
        header, rows = table(recording)
    except RecordingError as error:
        raise UsageError(str(error)) from None
    out = csv.writer(sys.stdout, lineterminator="\n")
    out.writerow(header)
    for row in rows[::args.every]:
        out.writerow(["" if v is None else repr(v) if isinstance(v, float) else v for v in row])
    return 0


def scene_source(name: str) -> str:
    """The generated module of scene `name` (a preset or a file), with a header saying its
    cache file and what runs it; nothing is compiled."""
    from ..physics.compiled import build
    from ..physics.scene import SceneError, load_scene
    from ..physics.simulator import code_of

    try:
        scene = load_scene(name)
    except SceneError as error:
        raise UsageError(str(error)) from None
    dynamics, step = code_of(scene)
    if not hasattr(step, "source") or hasattr(step, "rtol"):
        raise UsageError(f"scene {scene.name} runs {scene.method}, an adaptive step: it has "
                         "no compiled module (Python's path)")
    text, _ = build.module_source(dynamics, step)
    runs = ("the compiled path" if build.compilable(dynamics, step) else
            "Python's path (numba off or absent, or a servo's set-points)")
    module = f"{build.module_name(text)}.py"
    cached = (build.cache_dir() / module).is_file()
    header = [f"# {module}: " + (f"in the kernel cache {build.cache_dir()}" if cached else
                                 f"not compiled yet; its first compiled run writes it into "
                                 f"the kernel cache {build.cache_dir()}"),
              f"# scene {scene.name}: {scene.method}, effects "
              f"{', '.join(e.name for e in dynamics.active) or 'none'}; runs on {runs}"]
    return "\n".join(header) + "\n" + text


def not_a_recording(path: Path, given: str) -> str:
    """Why `path` is no file to inspect: a bag directory, another directory, or nothing."""
    if (path / "metadata.yaml").is_file():
        return (f"{given} is a bag (a rosbag2 directory); inspect reads Rerun recordings "
                f"(.rrd): `ros2 bag info {given}`, or read the bag with the rosbags library "
                "(README, Read a recording); `arm-sim run --bag B --rerun F.rrd` writes one run "
                "as both")
    if path.is_dir():
        return f"{given} is a directory; inspect reads a Rerun recording file (.rrd)"
    return f"{given}: no such file"


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("inspect", help="print a Rerun recording's properties and its "
                                              "series as CSV")
    p.add_argument("recording", metavar="REC.rrd", nargs="?",
                   help="a recording written by arm-sim or the node")
    p.add_argument("--source", metavar="SCENE",
                   help="print the module the scene (a preset or a .yaml file) compiles to")
    p.add_argument("--every", type=int, default=1, metavar="N", help="keep every Nth row")
    only = p.add_mutually_exclusive_group()
    only.add_argument("--properties", action="store_true", help="print only the properties")
    only.add_argument("--no-properties", action="store_true", help="print only the CSV table")
    p.set_defaults(func=cmd_inspect)
