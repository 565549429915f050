"""YAML files as people write them: YAML 1.2 numbers, no aliases, one clear error line.

PyYAML reads YAML 1.1, where `1e-3` (no dot) is text; YAML 1.2 and ROS 2's parameter
parser read it as a number, and so do we. A bare word is a bool where ROS 2's parser
(rcl_yaml_param_parser) reads one: YAML 1.1's yes/no/on/off/true/false, and y/n too, so a
scene file and the node's parameters read `estimate: off` (or `n`) alike. Anchors and aliases are refused outright: a
scene or parameter file never needs them, and a 700-byte alias bomb expands to gigabytes.
"""
from __future__ import annotations

import os
import re
import stat

import yaml

from .usage import UsageError

MAX_FILE_BYTES = 1_000_000
MAX_INT_DIGITS = 400          # 1e308 has 309 digits: more is beyond the doubles

# YAML 1.2 core schema floats: 1e-3, 1E3, .5, -2.5e+4, .inf, .nan.
FLOAT_1_2 = re.compile(r"""^(?:[-+]?(?:[0-9]+\.[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?
                          |[-+]?[0-9]+[eE][-+]?[0-9]+
                          |[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$""", re.X)


class YamlFileError(UsageError):
    """A YAML file that cannot be read as data; the message names the file and the place."""


class _Loader(yaml.SafeLoader):
    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise yaml.composer.ComposerError(None, None, "aliases (*name) are not allowed",
                                              event.start_mark)
        return super().compose_node(parent, index)

    def construct_mapping(self, node, deep=False):
        """A key given twice is refused: PyYAML keeps the last silently, and a scene whose
        damping is set twice would run on the one its author did not mean."""
        seen = set()
        for key_node, _ in node.value:
            key = key_node.value if isinstance(key_node, yaml.ScalarNode) else None
            if key is not None and key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"the key {key[:60]!r} is given twice", key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep)

    def construct_yaml_int(self, node):
        """An integer too long for any physical quantity (Python refuses to read one of more
        than 4300 digits) is refused with its place, not a traceback."""
        digits = len(node.value.lstrip("+-").replace("_", ""))
        if digits > MAX_INT_DIGITS:
            raise yaml.constructor.ConstructorError(
                None, None, f"an integer of {digits} digits is beyond any double",
                node.start_mark)
        return super().construct_yaml_int(node)


_Loader.add_constructor("tag:yaml.org,2002:int", _Loader.construct_yaml_int)
_Loader.bool_values = {**yaml.SafeLoader.bool_values, "y": True, "n": False}
_Loader.yaml_implicit_resolvers = {k: list(v) for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()}
for first in "-+.0123456789":
    _Loader.yaml_implicit_resolvers[first] = [
        (tag, regexp) for tag, regexp in _Loader.yaml_implicit_resolvers.get(first, [])
        if tag != "tag:yaml.org,2002:float"]
    _Loader.yaml_implicit_resolvers[first].insert(0, ("tag:yaml.org,2002:float", FLOAT_1_2))
for first in "yYnN":       # rcl's words for a bool beyond YAML 1.1's (ros_args.TRUE, FALSE)
    _Loader.yaml_implicit_resolvers.setdefault(first, []).append(
        ("tag:yaml.org,2002:bool", re.compile(r"^(?:y|Y|n|N)$")))


def loads(text: str, what: str):
    """Data from YAML text; YamlFileError naming `what` and the line for anything wrong."""
    return _parsed(lambda: yaml.load(text, Loader=_Loader), what)   # noqa: S506 (SafeLoader)


def compose(text: str, what: str):
    """The YAML node tree of `text` (scalars untyped, their quoting kept; aliases refused),
    for readers with typing rules of their own (ROS 2 parameters)."""
    if len(text) > MAX_FILE_BYTES:
        raise YamlFileError(f"{what} is larger than {MAX_FILE_BYTES} bytes")
    return _parsed(lambda: yaml.compose(text, Loader=_Loader), what)   # noqa: S506


def _parsed(parse, what: str):
    try:
        return parse()
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark or error.context_mark
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise YamlFileError(f"{what} is not valid YAML{where}: {error.problem or error.context}") \
            from None
    except (yaml.YAMLError, RecursionError) as error:
        raise YamlFileError(f"{what} is not valid YAML: {type(error).__name__}") from None


def load(path, what: str = "file"):
    """Data from a YAML file (at most MAX_FILE_BYTES), string keys only in mappings."""
    try:
        mode = os.stat(path).st_mode           # a pipe would block the read, a device not end
        if not stat.S_ISREG(mode):
            kind = "a directory" if stat.S_ISDIR(mode) else "not a regular file (a device or a pipe)"
            raise YamlFileError(f"{what} {path} is {kind}, not a YAML file")
        with open(path, "rb") as file:
            raw = file.read(MAX_FILE_BYTES + 1)
    except OSError as error:
        raise YamlFileError(f"cannot read {what} {path}: {error.strerror or error}") from None
    if len(raw) > MAX_FILE_BYTES:
        raise YamlFileError(f"{what} {path} is larger than {MAX_FILE_BYTES} bytes")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise YamlFileError(f"{what} {path} is not UTF-8 text") from None
    data = loads(text, f"{what} {path}")
    _check_keys(data, f"{what} {path}")
    return data


def _check_keys(data, what: str, depth: int = 0) -> None:
    if depth > 50:
        raise YamlFileError(f"{what} nests deeper than 50 levels")
    if isinstance(data, dict):
        for key, value in data.items():
            if not isinstance(key, str):
                raise YamlFileError(f"{what}: key {str(key)[:40]!r} is not text")
            _check_keys(value, what, depth + 1)
    elif isinstance(data, list):
        for value in data:
            _check_keys(value, what, depth + 1)
