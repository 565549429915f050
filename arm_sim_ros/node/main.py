"""`arm_sim_node`: the arm_sim ROS 2 node, on rclpy where ROS 2 is sourced, else on dds.

    arm_sim_node [--transport auto|rclpy|dds] [--duration SECONDS] [--quiet]
                 [--ros-args -p NAME:=VALUE ... --params-file FILE -r FROM:=TO ...]

On the dds transport the `--ros-args` are read here and resolved as rclcpp/rclpy resolve them:
every `/**` assignment (a parameter file's `/**:` section or a `-p`) in command-line order, then
the node's own sections (`arm_sim:` or `/arm_sim:`), which therefore win. Prints a one-line
status each second.
"""
from __future__ import annotations

import argparse
import logging
import signal
import sys
import time

import yaml

from . import transports
from ..interface import NODE_NAME
from ..usage import ArgumentParser, UsageError
from .parameters import ParameterRefused

LEVELS = {"debug": logging.DEBUG, "info": logging.INFO, "warn": logging.WARNING,
          "warning": logging.WARNING, "error": logging.ERROR, "fatal": logging.CRITICAL}


def split_ros_args(argv: list) -> tuple[list, list]:
    """(our arguments, the arguments inside --ros-args ... [--]), as rcl splits them."""
    ours, ros, inside = [], [], False
    for arg in argv:
        if arg == "--ros-args":
            inside = True
        elif arg == "--" and inside:
            inside = False
        elif inside:
            ros.append(arg)
        else:
            ours.append(arg)
    return ours, ros


def parse_ros_args(ros: list) -> dict:
    """`-p`, `--params-file`, `-r` and `--log-level` as rcl reads them."""
    assignments, remap, level = [], {}, None   # ("file", path) / ("param", name, value), in order
    items = iter(ros)
    for flag in items:
        value = next(items, None)
        if value is None:
            raise UsageError(f"--ros-args {flag} needs a value")
        if flag in ("-p", "--param"):
            name, value_text = _assignment(flag, value)
            assignments.append(("param", name, _yaml_value(name, value_text)))
        elif flag == "--params-file":
            assignments.append(("file", value))
        elif flag in ("-r", "--remap"):
            source, target = _assignment(flag, value)
            remap[source] = target
        elif flag == "--log-level":
            level = value.rsplit(":=", 1)[-1].lower()
            if level not in LEVELS:
                raise UsageError(f"--log-level {value!r}: choose one of {', '.join(LEVELS)}")
        else:
            raise UsageError(f"--ros-args {flag} is not supported on the dds transport "
                             "(supported: -p, --params-file, -r, --log-level)")
    return {"assignments": assignments, "remap": remap, "level": level}


def _assignment(flag: str, text: str) -> tuple[str, str]:
    name, sep, value = text.partition(":=")
    if not sep or not name:
        raise UsageError(f"{flag} {text!r} is not of the form name:=value")
    return name, value


def _yaml_value(name: str, text: str):
    """`-p` values are YAML, as in rcl: 100 is an integer, 1.0 a double, [1.0, 0.0] a list."""
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        raise UsageError(f"-p {name}:={text!r}: the value is not valid YAML") from None
    return "" if value is None else value


def read_params_file(path: str, full_name: str) -> tuple[dict, dict]:
    """(the `/**` parameters, this node's own) of a ROS 2 parameter file. Node keys may be
    nested namespaces (`robot: arm_sim: ros__parameters:`); nested parameter mappings become
    dotted names."""
    try:
        with open(path) as stream:
            data = yaml.safe_load(stream) or {}
    except OSError as error:
        raise UsageError(f"cannot read --params-file {path}: {error.strerror}") from None
    except yaml.YAMLError as error:
        raise UsageError(f"--params-file {path} is not valid YAML: {error}") from None
    if not isinstance(data, dict):
        raise UsageError(f"--params-file {path} must map node names to ros__parameters")
    wildcard, own = {}, {}
    for node, params in _node_sections(data):
        if node == "/**":
            wildcard.update(params)
        elif node == full_name:
            own.update(params)
    return wildcard, own


def _node_sections(data: dict, prefix: str = ""):
    for key, value in data.items():
        if not isinstance(value, dict):
            continue
        name = prefix + "/" + str(key).strip("/")
        if "ros__parameters" in value:
            yield name, _flatten(value["ros__parameters"] or {})
        else:
            yield from _node_sections(value, name)


def full_node_name(node_name: str = NODE_NAME, namespace: str = "/") -> str:
    return namespace.rstrip("/") + "/" + node_name


def load_params_file(path: str, node_name: str = NODE_NAME, namespace: str = "/") -> dict:
    """What one parameter file sets for this node."""
    wildcard, own = read_params_file(path, full_node_name(node_name, namespace))
    return wildcard | own


def _flatten(mapping: dict, prefix: str = "") -> dict:
    flat = {}
    for key, value in mapping.items():
        if isinstance(value, dict):
            flat.update(_flatten(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


def node_parameters(ros: dict, node_name: str, namespace: str) -> dict:
    """rclcpp's resolve_parameter_overrides: `/**` values first, then the node's own."""
    wildcard, own = {}, {}
    for kind, *what in ros["assignments"]:
        if kind == "file":
            file_wildcard, file_own = read_params_file(what[0], full_node_name(node_name, namespace))
            wildcard.update(file_wildcard)
            own.update(file_own)
        else:
            wildcard[what[0]] = what[1]
    params = wildcard | own
    params.pop("use_sim_time", None)  # every ROS node has it; the dds node keeps its own clock
    return params


def configure_logging(level: str | None) -> None:
    """ROS-style lines on stderr: [INFO] [1700000000.123456789] [arm_sim]: text."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_RosFormatter())
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(LEVELS[level or "info"])


class _RosFormatter(logging.Formatter):
    def format(self, record):
        level = {"WARNING": "WARN", "CRITICAL": "FATAL"}.get(record.levelname, record.levelname)
        return f"[{level}] [{record.created:.9f}] [{record.name}]: {record.getMessage()}"


def run_dds(ros_argv: list, duration: float | None, status) -> int:
    from .messages import DiscoveryError
    from .transports.dds import DdsArmSimNode

    ros = parse_ros_args(ros_argv)
    configure_logging(ros["level"])
    name = ros["remap"].pop("__node", ros["remap"].pop("__name", NODE_NAME))
    namespace = "/" + ros["remap"].pop("__ns", "/").strip("/")
    try:
        node = DdsArmSimNode(node_parameters(ros, name, namespace), name=name,
                             namespace=namespace, remap=ros["remap"])
    except DiscoveryError as error:
        raise UsageError(str(error)) from None
    try:
        node.spin(duration, status)
    finally:
        node.close()
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(prog="arm_sim_node", description=__doc__.splitlines()[0])
    parser.add_argument("--transport", default="auto", choices=("auto",) + transports.TRANSPORTS,
                        help="rclpy when it imports (auto), else dds")
    parser.add_argument("--duration", type=float, metavar="SECONDS",
                        help="stop after this much simulated time (default: run until Ctrl-C)")
    parser.add_argument("--quiet", action="store_true", help="no status line each second")
    return parser


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    ours, ros_argv = split_ros_args(argv)
    # launch stops nodes with SIGINT, then SIGTERM: both end the loop the same clean way.
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        args = build_parser().parse_args(ours)
        if args.duration is not None and not (args.duration >= 0 and args.duration < float("inf")):
            raise UsageError(f"--duration {args.duration} must be a finite number of seconds >= 0")
        transport = transports.choose(args.transport)
        status = None if args.quiet else _print_status
        if transport == "rclpy":
            from .transports.rclpy_transport import run
            return run(["arm_sim_node", "--ros-args", *ros_argv], args.duration, status)
        return run_dds(ros_argv, args.duration, status)
    except (UsageError, ParameterRefused, transports.TransportUnavailable) as error:
        print(f"arm_sim_node: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 0


def _print_status(line: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {line}", flush=True)


if __name__ == "__main__":
    sys.exit(main())
