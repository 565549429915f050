"""`arm_sim_node`: the arm_sim ROS 2 node, on rclpy where ROS 2 is sourced, else on dds.

    arm_sim_node [--transport auto|rclpy|dds] [--duration SECONDS] [--quiet]
                 [--ros-args -p NAME:=VALUE ... --params-file FILE -r FROM:=TO ...]

On the dds transport the `--ros-args` are read here and resolved as rclcpp/rclpy resolve them:
every `/**` assignment (a parameter file's `/**:` section or a `-p`) in command-line order, then
the node's own sections (`arm_sim:` or `/arm_sim:`), which therefore win. Says at start what
is on, prints a one-line status each second, and says at the end where it stopped and what it
wrote (--quiet: warnings and errors only).
"""
from __future__ import annotations

import argparse
import logging
import sys
import time

from . import transports
from ..interface import NODE_NAME
from ..physics.compiled.cache import log_pulse
from ..physics.scene import MAX_DURATION
from ..usage import DONE, REFUSED, ArgumentParser, UsageError, exit_as_main, one_line
from .stop import Stop, stopped_while_starting
from .params.parameters import PARAMETERS, when_changed
from .params.values import ParameterRefused
from .params.ros_args import (LOG_LEVELS, load_params_file, node_identity,
                              node_parameters, parse_ros_args, split_ros_args)  # noqa: F401

LEVELS = dict(zip(LOG_LEVELS, (logging.DEBUG, logging.INFO, logging.WARNING, logging.WARNING,
                               logging.ERROR, logging.CRITICAL)))


def configure_logging(level: str | None) -> None:
    """ROS-style lines on stderr: [INFO] [1700000000.123456789] [arm_sim]: text."""
    handler = _Stderr()
    handler.setFormatter(_RosFormatter())
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(LEVELS[level or "info"])


class _Stderr(logging.StreamHandler):
    """Lines go to sys.stderr as it is when each is written: a handler holding the stream of
    its day outlives a redirect (a test's capture), then a later library line (matplotlib's
    first font scan) meets a closed file."""
    stream = property(lambda self: sys.stderr, lambda self, value: None)


class _RosFormatter(logging.Formatter):
    def format(self, record):
        level = {"WARNING": "WARN", "CRITICAL": "FATAL"}.get(record.levelname, record.levelname)
        return f"[{level}] [{record.created:.9f}] [{record.name}]: {record.getMessage()}"


def run_dds(ros_argv: list, duration: float | None, status, stop=None, quiet=False) -> int:
    from .wire.messages import close_domains
    from .transports.dds import DdsArmSimNode

    ros = parse_ros_args(ros_argv)
    configure_logging(ros["level"] or ("warn" if quiet else None))
    name, namespace, rules = node_identity(ros["remap"], NODE_NAME)
    node = DdsArmSimNode(node_parameters(ros, name, namespace), name=name, namespace=namespace,
                         remap=rules)   # a DiscoveryError is a UsageError: one line, exit 2
    early = stop is not None and stop.requested     # a stop while it started: now, whole
    if stop is not None:
        stop.starting = False
    try:
        node.spin(duration, status, stopped=stop and (lambda: stop.requested))
    finally:
        path = node.core.config.values["rerun_path"]
        node.close()
        close_domains()      # Cyclone torn down now, in order, not by interpreter teardown
        if early:
            print(stopped_while_starting(stop, f"its recording {path} holds its start" if path
                                         else "no recording was asked for"), file=sys.stderr)
    return 0


ROS_TYPES = {"float": "double", "int": "integer", "str": "string", "bool": "bool", "float_pair": "double[2]",
             "float_or_pair": "double[1|2]", "str_list": "string[]"}


def parameter_help() -> str:
    """Every parameter from the one table: ROS type, default (scene release) and meaning."""
    from .params.parameters import scene_defaults

    defaults = scene_defaults("release")
    lines = ["parameters (--ros-args -p NAME:=VALUE, or --params-file FILE with "
             "arm_sim: ros__parameters: NAME: VALUE;",
             "scene-derived defaults are those of scene release; `ros2 param set` changes "
             "them while it runs, as the last column says;",
             "an effect's keys are named as in a scene file, effect.key; an effect no key "
             "names is absent):"]
    for spec in PARAMETERS:
        default = "not set" if defaults[spec.name] is None else f"{defaults[spec.name]!r}"
        lines.append(f"  {spec.name:<30} {ROS_TYPES[spec.kind]:<11} {default:<26} "
                     f"{when_changed(spec.name)}")
        lines.append(f"      {spec.description}")
    lines.append("example: arm_sim_node --ros-args -p scene:=damped_release "
                 "-p publish_rate:=50.0 -p rerun_path:=arm.rrd")
    lines.append("         arm_sim_node --ros-args -p friction.coulomb:=[0.5,0.1] "
                 "-p effort_limits:=[15.0,10.0]")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(prog="arm_sim_node", description=__doc__.split("\n\n")[0],
                            epilog=parameter_help(),
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--transport", default="auto", choices=("auto",) + transports.TRANSPORTS,
                        help="rclpy when it imports (auto), else dds")
    parser.add_argument("--duration", type=float, metavar="SECONDS",
                        help="stop after this much simulated time (default: run until Ctrl-C)")
    parser.add_argument("--quiet", action="store_true",
                        help="no status line each second and no info lines: warnings and "
                             "errors only (as --ros-args --log-level warn)")
    return parser


def main(argv=None, stop: Stop | None = None) -> int:
    """The node; `stop`: the signals' handler, installed already by the console script
    (entry.py) before the node's modules were imported."""
    argv = sys.argv[1:] if argv is None else list(argv)
    ours, ros_argv = split_ros_args(argv)
    if stop is None:
        stop = Stop()
        stop.starting = True
        stop.install()
    try:
        args = parse_ours(ours)
        if args.duration is not None and not 0 <= args.duration <= MAX_DURATION:
            raise UsageError(f"--duration {args.duration:g} must be a number of seconds from 0 "
                             f"to {MAX_DURATION:g}")
        transport = transports.choose(args.transport)
        status = None if args.quiet else _print_status
        log_pulse()          # a first compile at the first tick: "still compiling" each 10 s
        if transport == "rclpy":
            if stop.requested:            # rclpy.init takes the signals over: said now
                print(stopped_while_starting(stop, "no recording was written"), file=sys.stderr)
                return DONE
            from .transports.rclpy_transport import run
            quiet = ["--log-level", "warn"] if args.quiet else []     # a later one wins
            return run(["arm_sim_node", "--ros-args", *quiet, *ros_argv], args.duration, status)
        return run_dds(ros_argv, args.duration, status, stop, args.quiet)
    except (UsageError, ParameterRefused, transports.TransportUnavailable) as error:
        print(f"arm_sim_node: error: {one_line(error)}", file=sys.stderr)
        return REFUSED
    except KeyboardInterrupt:
        if stop.starting:                 # a second signal while it started: it did not wait
            print(stopped_while_starting(stop, "no recording was finished"), file=sys.stderr)
        return DONE
    except Exception:
        # A signal met inside numba's first compile is dropped in llvmlite's callback and
        # leaves numba's half-built library to fail ("no compiled object yet"): the stop
        # asked for is what happened, not a fault.
        if stop.requested:
            return DONE
        raise


ROS_FLAGS = ("-p", "--param", "--params-file", "-r", "--remap", "--log-level", "-e",
             "--enclave")


def parse_ours(ours: list) -> argparse.Namespace:
    """The node's own options; ROS arguments given without --ros-args are refused with the
    command line that would take them (rcl reads them only after --ros-args)."""
    try:
        return build_parser().parse_args(ours)
    except UsageError as error:
        ros = [a for a in ours if a in ROS_FLAGS or ":=" in a]
        if not ros:
            raise
        at = ours.index(ros[0])
        fixed = " ".join(["arm_sim_node", *ours[:at], "--ros-args", *ours[at:]])
        raise UsageError(f"{error}; ROS arguments go after --ros-args: {fixed}") from None


def _print_status(line: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {line}", flush=True)


if __name__ == "__main__":
    exit_as_main(main())
