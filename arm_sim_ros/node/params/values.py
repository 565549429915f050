"""One parameter value checked as its kind: the refusal that names the parameter and says why,
and the coercion of what a transport hands over (rcl's readings, rclpy arrays, YAML) into
the value the node keeps. The declarations themselves are in parameters.py."""
from __future__ import annotations

from ...physics.model import BRIEF, ParameterError, brief
from ...physics.scene import SceneError, coerce_value, in_radians
from ...usage import one_line


class ParameterRefused(ValueError):
    """A parameter value the node will not take; str() names the parameter and the reason."""

    def __init__(self, name: str, reason: str):
        reason = shorten(one_line(reason))   # one log line, never a 100 KB one
        super().__init__(f"parameter {brief(name, 60)} refused: {reason}")
        self.name, self.reason = name, reason


def shorten(text: str, limit: int = 3 * BRIEF) -> str:
    """`text` cut to `limit` characters, saying how long it was."""
    return text if len(text) <= limit else f"{text[:limit]}… ({len(text)} chars)"


SCENE_KINDS = {"float": "float", "int": "int", "str": "str", "float_pair": "pair",  # node -> scene
               "float_or_pair": "float_or_pair"}


def coerce(spec, value):
    """The value in the kind of `spec` (a parameters.ParameterSpec), or ParameterRefused.
    Numbers, text and pairs are checked as scene values are; integers pass as doubles
    (`-p publish_rate:=100`)."""
    kind, name = spec.kind, spec.name
    if kind != "str":                 # an angle in degrees, `90deg`, as everywhere
        try:
            value = in_radians(name, value)
        except SceneError as error:
            raise ParameterRefused(name, str(error)) from None
    if spec.effect is not None:
        # not set: the effect's default, or no effect at all. `ros2 param dump` writes a
        # parameter not set as YAML null, which rcl reads back as the text "null".
        if value is None or value == "null":
            return None
        try:
            value = spec.effect.coerce(name.partition(".")[0], value)
        except ParameterError as error:
            raise ParameterRefused(name, str(error)) from None
        return list(value) if isinstance(value, tuple) else value
    if kind in SCENE_KINDS:
        try:
            value = coerce_value(name, SCENE_KINDS[kind], value)
        except SceneError as error:
            raise ParameterRefused(name, str(error)) from None
        return list(value) if isinstance(value, tuple) else value
    if kind == "bool":
        if not isinstance(value, bool):
            raise ParameterRefused(name, f"must be true or false, got {brief(value)}")
        return value
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
        raise ParameterRefused(name, f"must be a list, got {brief(value)}")
    if not all(isinstance(v, str) for v in value):
        raise ParameterRefused(name, f"must be a list of text, got {brief(list(value))}")
    return list(value)
