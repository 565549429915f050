"""What the rcl_interfaces parameter services and `~/reset` answer, for a transport that has no
rclpy to answer them (the dds transport). Values are plain Python; the transport turns them
into messages.

The answers are the ones rclpy's ParameterService gives for the rclpy transport's node
(rclpy/parameter_service.py and node.py, Jazzy): undeclared parameters are not allowed, so a
get, describe or get-types naming an unknown parameter answers with an empty list; set
applies each parameter on its own, set-atomically all or nothing; `scene` and
`robot_description` are read-only (READ_ONLY, as the rclpy transport declares them); every
other parameter is dynamically typed (an integer is a fine double: the node core
checks every value and refuses with a reason, changing nothing); an effect's key the scene
does not name is declared NOT_SET, as rclpy declares a dynamically typed parameter without
a value. A successful set publishes a parameter event listing the parameters set, with the
values the node now holds.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..params.parameters import PARAMETERS, READ_ONLY, SPECS
from ..params.values import ParameterRefused, shorten

# rcl_interfaces/msg/ParameterType
(NOT_SET, BOOL, INTEGER, DOUBLE, STRING, BYTE_ARRAY, BOOL_ARRAY, INTEGER_ARRAY, DOUBLE_ARRAY,
 STRING_ARRAY) = range(10)
KIND_TYPES = {"str": STRING, "float": DOUBLE, "int": INTEGER, "bool": BOOL, "float_pair": DOUBLE_ARRAY,
              "str_list": STRING_ARRAY}
SEPARATOR = "."                  # rclpy's PARAMETER_SEPARATOR_STRING
DEPTH_RECURSIVE = 0              # rcl_interfaces/srv/ListParameters.DEPTH_RECURSIVE


@dataclass(frozen=True)
class Descriptor:
    """rcl_interfaces/msg/ParameterDescriptor without ranges (the node declares none)."""
    name: str
    type: int
    description: str
    read_only: bool
    dynamic_typing: bool


@dataclass(frozen=True)
class SetResult:
    """rcl_interfaces/msg/SetParametersResult."""
    successful: bool
    reason: str = ""


def parameter_type(name: str, value) -> int:
    """The ParameterType a value of the node's parameter `name` is served as; a damping given
    as one number is a double, as a pair a double array; an effect key not set is NOT_SET."""
    kind = SPECS[name].kind
    if value is None:
        return NOT_SET
    if kind == "float_or_pair":
        return DOUBLE if isinstance(value, (int, float)) else DOUBLE_ARRAY
    return KIND_TYPES[kind]


class ParameterServices:
    """The node's side of list/get/set/set-atomically/describe/get-types and reset, over an
    ArmSimCore. `on_set(names)` is called after every successful set (the transport publishes
    the parameter event and adapts its timers)."""

    def __init__(self, core, log, on_set=None):
        self.core, self.log, self.on_set = core, log, on_set

    def value(self, name: str) -> tuple[int, object]:
        value = self.core.config.values[name]
        return parameter_type(name, value), value

    def list(self, prefixes: list, depth: int) -> tuple[list, list]:
        """(names, prefixes) as rclpy's Node.list_parameters computes them."""
        def shallow(text):
            return text.count(SEPARATOR) < depth

        recursive = not prefixes and depth == DEPTH_RECURSIVE
        names, found_prefixes = [], []
        for name in (spec.name for spec in PARAMETERS):
            if not recursive and not (not prefixes and shallow(name)):
                if not any(name == prefix or (name.startswith(prefix + SEPARATOR) and (
                        depth == DEPTH_RECURSIVE or shallow(name[len(prefix) + 1:])))
                        for prefix in prefixes):
                    continue
            names.append(name)
            if SEPARATOR in name:
                prefix = name[:name.rfind(SEPARATOR)]
                if prefix not in found_prefixes:
                    found_prefixes.append(prefix)
        return names, found_prefixes

    def get(self, names: list) -> list:
        """[(type, value)] per name; [] when any name is not a parameter of the node."""
        if not all(name in SPECS for name in names):
            return []
        return [self.value(name) for name in names]

    def types(self, names: list) -> list:
        return [t for t, _ in self.get(names)]

    def describe(self, names: list) -> list:
        if not all(name in SPECS for name in names):
            return []
        return [Descriptor(name, self.value(name)[0], SPECS[name].description,
                           read_only=name in READ_ONLY, dynamic_typing=name not in READ_ONLY)
                for name in names]

    def set_each(self, parameters: list) -> list:
        """One SetResult per (name, value), each set on its own, in order."""
        return [self.set_atomically([parameter]) for parameter in parameters]

    def set_atomically(self, parameters: list) -> SetResult:
        """All (name, value) pairs applied together, or none of them."""
        names = [name for name, _ in parameters]
        undeclared = [name for name in names if name not in SPECS]
        if undeclared:
            return self._refused(f"Invalid access to undeclared parameter(s): {undeclared}")
        for name in names:
            if name in READ_ONLY:
                return self._refused(f"Trying to set a read-only parameter: {name}.")
        try:
            self.core.set_parameters(dict(parameters))
        except ParameterRefused as refusal:
            return self._refused(str(refusal))
        except Exception as error:   # noqa: BLE001 - a bug must not leave a client unanswered
            self.log.error(f"set_parameters {names}: {type(error).__name__}: {error}")
            return self._refused(could_not_apply(names, error))
        if self.on_set is not None:
            self.on_set(list(dict.fromkeys(names)))
        return SetResult(True)

    def _refused(self, reason: str) -> SetResult:
        reason = shorten(reason)
        self.log.warning(reason)
        return SetResult(False, reason)

    def reset(self) -> tuple[bool, str]:
        """std_srvs/srv/Trigger on ~/reset: (success, message), as the rclpy transport says it."""
        self.core.reset()
        return True, f"scene {self.core.config.scene.name} restarted from its initial state"


def could_not_apply(names, error: Exception) -> str:
    """The refusal when applying raised something other than a refusal (a bug in the physics
    rebuild): the client is answered and the node goes on, on both transports."""
    return (f"parameters {', '.join(names)} refused: the node could not apply them "
            f"({type(error).__name__}); nothing changed")
