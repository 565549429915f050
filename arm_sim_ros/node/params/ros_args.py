"""`--ros-args` on the dds transport, read as rcl reads them.

Values (`-p name:=value` and parameter files) follow rcl_yaml_param_parser's rules, not
PyYAML's: an unquoted scalar is a bool if it is one of rcl's words (true/yes/on/y...), an
integer if C's strtol(base 0) reads all of it without overflow (so 0x1F and 010 are 31 and
8), a double if strtod does (1e-3, .5, inf, .nan), else a string; a quoted scalar is a
string; a sequence holds one type. Parameters are then resolved as rclcpp/rclpy resolve
them: every `/**` assignment in command-line order, then the node's own sections.
"""
from __future__ import annotations

import math
import re
from fractions import Fraction

import yaml

from ...interface import NODE_NAME
from ...usage import UsageError
from ...yaml_files import YamlFileError, compose

TRUE = {"Y", "y", "yes", "Yes", "YES", "true", "True", "TRUE", "on", "On", "ON"}
FALSE = {"N", "n", "no", "No", "NO", "false", "False", "FALSE", "off", "Off", "OFF"}
SPECIAL_FLOATS = {f"{sign}.{word}" for sign in ("", "+", "-") for word in ("inf", "Inf", "INF")}
SPECIAL_FLOATS |= {".nan", ".NaN", ".NAN"}
INT64 = (-2 ** 63, 2 ** 63 - 1)
STRTOL = re.compile(r"[-+]?(?:0[xX][0-9a-fA-F]+|0[0-7]*|[1-9][0-9]*)")
STRTOD = re.compile(r"[-+]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?"
                    r"|inf(?:inity)?|nan)", re.IGNORECASE)
STRTOD_HEX = re.compile(r"[-+]?0[xX](?:[0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+)"
                        r"(?:[pP][-+]?[0-9]+)?")
LOG_LEVELS = ("debug", "info", "warn", "warning", "error", "fatal")


DBL_MIN = 2.2250738585072014e-308     # the smallest normal double


def _exact(text: str, value: float) -> bool:
    """Whether the double `value` is exactly the number `text` writes (decimal or hex)."""
    exact = _hex_fraction(text) if STRTOD_HEX.fullmatch(text) else Fraction(text)
    return Fraction(value) == exact


def _hex_fraction(text: str) -> Fraction:
    sign = -1 if text.startswith("-") else 1
    mantissa, _, exponent = text.lstrip("+-")[2:].lower().partition("p")
    whole, _, fraction = mantissa.partition(".")
    digits = int(whole + fraction or "0", 16)
    return sign * Fraction(digits) * Fraction(2) ** (int(exponent or 0) - 4 * len(fraction))


def rcl_scalar(text: str, quoted: bool = False):
    """One scalar as rcl's get_value types it: bool, int, float or str."""
    if quoted:
        return text
    if text in TRUE or text in FALSE:
        return text in TRUE
    if STRTOL.fullmatch(text) and len(text) <= 25:   # longer overflows int64 (and int())
        value = int(text, 16) if text.lstrip("+-")[:2] in ("0x", "0X") else \
            int(text, 8) if text.lstrip("+-").startswith("0") and len(text.lstrip("+-")) > 1 \
            else int(text)
        if text.startswith("-") and text.lstrip("+-")[:2] in ("0x", "0X"):
            value = -abs(value)
        if INT64[0] <= value <= INT64[1]:
            return value
    if text in SPECIAL_FLOATS:
        return float(text.replace(".", "", 1))
    if STRTOD.fullmatch(text) or STRTOD_HEX.fullmatch(text):
        value = float.fromhex(text) if STRTOD_HEX.fullmatch(text) else float(text)
        digits = re.sub(r"[eEpP].*", "", text.lstrip("+-"))
        overflow = math.isinf(value) and "inf" not in text.lower()
        # glibc's strtod sets ERANGE (rcl then reads text) for a result rounded to zero or
        # to a subnormal; a subnormal it holds exactly (0x1p-1074) is a double
        underflow = (value == 0.0 and any(c not in "0.xX" for c in digits)) or \
            (value != 0.0 and abs(value) < DBL_MIN and not _exact(text, value))
        if not (overflow or underflow):
            return value
    return text


def rcl_value(node, what: str):
    """A composed YAML node as an rcl parameter value (a scalar or a one-type list)."""
    if isinstance(node, yaml.ScalarNode):
        if node.style is None and node.value == "":
            raise UsageError(f"{what} has no value")
        return rcl_scalar(node.value, quoted=node.style in ("'", '"'))
    if isinstance(node, yaml.SequenceNode):
        values = [rcl_value(item, what) if isinstance(item, yaml.ScalarNode) else
                  _nested(what) for item in node.value]
        if len({type(v) for v in values}) > 1:
            degrees = any(isinstance(v, str) and v.endswith("deg") for v in values)
            raise UsageError(f"{what}: a list must hold one type (all numbers with a dot, all "
                             f"integers, all text or all true/false), got {node_text(node)}"
                             + ("; an angle in degrees takes deg on every number: "
                                "[90deg, 0deg]" if degrees else ""))
        return values
    raise UsageError(f"{what}: a parameter value is a scalar or a list, not a mapping")


def _nested(what: str):
    raise UsageError(f"{what}: a parameter value cannot nest lists")


def node_text(node) -> str:
    return "[" + ", ".join(getattr(item, "value", "?") for item in node.value) + "]"


def rcl_parameters(node, what: str) -> dict:
    """A `ros__parameters` mapping; nested mappings become dotted names."""
    if not isinstance(node, yaml.MappingNode):
        raise UsageError(f"{what}: ros__parameters must map names to values")
    flat = {}
    for key, value in node.value:
        name = str(key.value)
        if isinstance(value, yaml.MappingNode):
            flat.update({f"{name}.{k}": v for k, v in rcl_parameters(value, what).items()})
        else:
            flat[name] = rcl_value(value, f"{what}: {name}")
    return flat


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
        if flag not in ("-p", "--param", "--params-file", "-r", "--remap", "--log-level"):
            raise UsageError(f"--ros-args {flag} is not supported on the dds transport "
                             "(supported: -p, --params-file, -r, --log-level)")
        value = next(items, None)
        if value is None:
            raise UsageError(f"--ros-args {flag} needs a value")
        if flag in ("-p", "--param"):
            name, value_text = _assignment(flag, value)
            assignments.append(("param", name, _param_value(name, value_text)))
        elif flag == "--params-file":
            assignments.append(("file", value))
        elif flag in ("-r", "--remap"):
            source, target = _assignment(flag, value)
            remap.setdefault(source, target)      # rcl: the first rule that matches wins
        else:
            level = value.rsplit(":=", 1)[-1].lower()
            if level not in LOG_LEVELS:
                raise UsageError(f"--log-level {value!r}: choose one of {', '.join(LOG_LEVELS)}")
    return {"assignments": assignments, "remap": remap, "level": level}


def _assignment(flag: str, text: str) -> tuple[str, str]:
    name, sep, value = text.partition(":=")
    if not sep or not name:
        raise UsageError(f"{flag} {text!r} is not of the form name:=value")
    return name, value


def _param_value(name: str, text: str):
    what = f"-p {name}:={text[:40]!r}"
    node = compose(text, what)
    if node is None:      # `-p name:=""` in a shell: the shell took the quotes, as rcl sees it
        raise UsageError(f"{what} has no value; empty text is YAML's '', which the shell "
                         f"must keep: -p \"{name}:=''\"")
    return rcl_value(node, what)


def read_params_file(path: str, full_name: str) -> tuple[dict, dict]:
    """(the `/**` parameters, this node's own) of a ROS 2 parameter file. Node keys may be
    nested namespaces (`robot: arm_sim: ros__parameters:`)."""
    what = f"--params-file {path}"
    try:
        with open(path, "rb") as stream:
            text = stream.read().decode("utf-8")
    except OSError as error:
        raise UsageError(f"cannot read {what}: {error.strerror}") from None
    except UnicodeDecodeError:
        raise UsageError(f"{what} is not UTF-8 text") from None
    root = compose(text, what)
    if root is None:
        return {}, {}
    if not isinstance(root, yaml.MappingNode):
        raise UsageError(f"{what} must map node names to ros__parameters")
    wildcard, own = {}, {}
    for node, params in _node_sections(root, what):
        if node == "/**":
            wildcard.update(params)
        elif node == full_name:
            own.update(params)
    return wildcard, own


def _node_sections(mapping, what: str, prefix: str = ""):
    for key, value in mapping.value:
        if not isinstance(value, yaml.MappingNode):
            continue
        name = prefix + "/" + str(key.value).strip("/")
        section = {k.value: v for k, v in value.value}
        if "ros__parameters" in section:
            yield name, rcl_parameters(section["ros__parameters"], what)
        else:
            yield from _node_sections(value, what, name)


def full_node_name(node_name: str = NODE_NAME, namespace: str = "/") -> str:
    """`/arm_sim`, or `/robot/arm_sim` in namespace `/robot`."""
    return namespace.rstrip("/") + "/" + node_name


NODE_NAME_RULE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def node_identity(remap: dict, node_name: str = NODE_NAME) -> tuple[str, str, dict]:
    """(node name, namespace, the name remapping rules) of `-r` rules as rcl reads them:
    `__node:=` (or `__name:=`) renames the node, `__ns:=` moves it; a rule prefixed with a
    node name (`arm_sim:__node:=other`, `arm_sim:joint_states:=js`) is for that node only."""
    rules = {}
    for source, target in remap.items():
        node, colon, rule = source.rpartition(":")
        if not colon or node == node_name:
            rules.setdefault(rule, target)
    name = rules.pop("__node", rules.pop("__name", node_name))   # both popped; __node wins
    namespace = "/" + rules.pop("__ns", "/").strip("/")
    if not NODE_NAME_RULE.fullmatch(name):
        raise UsageError(f"-r __node:={name!r}: a node name is letters, digits and underscores, "
                         "not starting with a digit")
    return name, namespace, rules


def expand_name(name: str, node_name: str, namespace: str) -> str:
    """rcl_expand_topic_name: `~` is the node's full name, a relative name goes in the
    namespace, an absolute one stays."""
    if name == "~" or name.startswith("~/"):
        return full_node_name(node_name, namespace) + name[1:]
    return name if name.startswith("/") else namespace.rstrip("/") + "/" + name


def remap_name(name: str, node_name: str, namespace: str, rules: dict | None = None) -> str:
    """A topic or service name, expanded, after the first `-r` rule whose source expands to
    the same name (rcl_remap_topic_name / rcl_remap_service_name)."""
    expanded = expand_name(name, node_name, namespace)
    for source, target in (rules or {}).items():
        if expand_name(source, node_name, namespace) == expanded:
            return expand_name(target, node_name, namespace)
    return expanded


def load_params_file(path: str, node_name: str = NODE_NAME, namespace: str = "/") -> dict:
    """What one parameter file sets for this node."""
    wildcard, own = read_params_file(path, full_node_name(node_name, namespace))
    return wildcard | own


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
    if params.pop("use_sim_time", False) is True:
        raise UsageError("use_sim_time:=true is not supported on the dds transport: the node "
                         "keeps simulated time itself (stamps are start time + simulated time)")
    return params
