"""What a node parameter is: its declaration (ParameterSpec: name, kind, default, meaning,
when it may change) and the refusal of a value (ParameterRefused), for parameters.py's list."""
from __future__ import annotations

from dataclasses import dataclass

from ...physics.model import BRIEF, brief
from ...physics.scene import Scene
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


# When a parameter may change (main.py's --help prints it): the one place it is decided.
START = "start only"                   # refused while running (START_ONLY)
KEPT = "live, state kept"              # the physics changes from the next step (LIVE)
RESTART = "live, restarts the scene"   # a Scene field: the scene restarts with it
ANYTIME = "live"


@dataclass(frozen=True)
class ParameterSpec:
    name: str
    kind: str              # "str", "float", "bool", "float_pair", "str_list"
    default: object        # a value, or a function scene -> value for scene-derived defaults
    meaning: str
    scene_field: bool = False   # True when the value is a Scene field (changing it rebuilds)
    effect: object = None       # an effect's key: the physics Parameter that checks it
    when: str = ANYTIME         # START, KEPT, RESTART or ANYTIME

    def default_for(self, scene: Scene):
        return self.default(scene) if callable(self.default) else self.default

    @property
    def description(self) -> str:
        """The meaning, and when it may change if not while running."""
        if self.effect is not None:
            return f"{self.meaning} ({'chosen at start' if self.when == START else 'changes live'})"
        return self.meaning + ("; chosen at start" if self.when == START else "")
