"""Which scene each sample of a sweep runs: a pure function of (the base scene, the
--vary keys, the seed, the sample's index), so that no worker count, order or scheduler can
change a row.

The grid keys (lists, lin:, log:, range:) form their product, the first --vary varying
slowest; at each grid point `draws` samples draw the distributions' keys, sample `index`
from numpy's Generator(Philox(SeedSequence([seed, index]))), the keys in the order given.
Sample `index` is grid point index // draws.
"""
from __future__ import annotations

from dataclasses import dataclass
from math import prod

import numpy as np

from ...physics.scene import Scene, SceneError
from .spec import Vary, kind_of

DEFAULT_DRAWS = 100        # Monte Carlo samples per grid point when --samples is not given
MAX_SAMPLES = 10_000_000   # rows a table may hold
BLOCKS = 64                # a sweep is cut into about this many blocks (tasks) ...
MAX_BLOCK = 256            # ... of at most this many samples


@dataclass(frozen=True)
class Plan:
    varies: tuple
    seed: int = 0
    draws: int = 1

    @classmethod
    def make(cls, varies, samples: int | None, seed: int) -> "Plan":
        varies = tuple(varies)
        if not varies:
            raise SceneError("a sweep needs at least one --vary KEY=SPEC")
        seen = {}
        for v in varies:
            for name in (v.field, v.key):
                other = seen.get(name)
                if other is not None and (other.joint is None or v.joint is None
                                          or other.joint == v.joint):
                    raise SceneError(f"--vary {other.key} and --vary {v.key} set the same "
                                     "value; give it once")
            seen[v.field] = seen[v.key] = v
        if not 0 <= seed < 2 ** 63:
            raise SceneError(f"--seed {seed} must be a whole number from 0 to 2^63 - 1")
        drawn = any(v.drawn for v in varies)
        if samples is not None and samples < 1:
            raise SceneError(f"--samples {samples} must be at least 1")
        if samples is not None and samples > 1 and not drawn:
            raise SceneError(f"--samples {samples}: no --vary draws from a distribution "
                             "(uniform:, normal:, lognormal:, integers:), so every sample of "
                             "a grid point would be the same; leave --samples out")
        plan = cls(varies, seed, (samples or DEFAULT_DRAWS) if drawn else 1)
        if plan.count > MAX_SAMPLES:
            raise SceneError(f"{plan.count} samples ({plan.shape_text}) is more than a table "
                             f"holds here ({MAX_SAMPLES}); sweep in parts")
        return plan

    @property
    def grid(self) -> tuple:
        return tuple(v for v in self.varies if not v.drawn)

    @property
    def points(self) -> int:
        return prod(len(v.values) for v in self.grid)

    @property
    def count(self) -> int:
        return self.points * self.draws

    @property
    def shape_text(self) -> str:
        """How the samples are made, e.g. `grid 20 x 20 x 2, 100 draws each`."""
        grid = " x ".join(str(len(v.values)) for v in self.grid)
        if self.draws == 1:
            return f"grid {grid}"
        return f"{self.draws} draws" + (f" at each of {self.points} grid points ({grid})"
                                        if grid else "")

    @property
    def columns(self) -> tuple:
        return tuple(c for v in self.varies for c in v.columns)

    def values(self, index: int) -> tuple:
        """Each --vary's value for sample `index`, in the order given."""
        point, draw = divmod(index, self.draws)
        at = {}
        for v in reversed(self.grid):              # the first --vary varies slowest
            point, k = divmod(point, len(v.values))
            at[v.key] = v.values[k]
        if any(v.drawn for v in self.varies):
            rng = np.random.Generator(np.random.Philox(np.random.SeedSequence([self.seed, index])))
            for v in self.varies:
                if v.drawn:
                    at[v.key] = v.draw(rng)
        return tuple(at[v.key] for v in self.varies)

    def cells(self, values) -> tuple:
        return tuple(c for v, value in zip(self.varies, values) for c in v.cells(value))

    def scene(self, base: Scene, values) -> Scene:
        """The sample's scene, or SceneError saying why it cannot be simulated."""
        return base.replace(**overrides(base, self.varies, values))

    def blocks(self) -> list:
        """[(first, stop)] of the samples run together: a function of the count alone, so
        that every run of the sweep cuts it alike."""
        size = min(MAX_BLOCK, max(1, -(-self.count // BLOCKS)))
        return [(first, min(first + size, self.count)) for first in range(0, self.count, size)]


def overrides(base: Scene, varies, values) -> dict:
    """{scene key: value} for Scene.replace: a per-joint key's one number on both joints,
    a KEY[i] on joint i (the other joint keeps the scene's value, or another KEY[j]'s)."""
    found = {}
    for v, value in zip(varies, values):
        if v.joint is None:
            found[v.field] = (value, value) if _pair_key(base, v.field, value) else value
            continue
        pair = list(found.get(v.field) or _current_pair(base, v.field))
        pair[v.joint] = value
        found[v.field] = tuple(pair)
    return found


def _pair_key(base: Scene, field: str, value) -> bool:
    """Whether one number for `field` stands for both joints (a pair key)."""
    return not isinstance(value, (tuple, str)) and kind_of(field) in ("pair", "pair_or_none")


def _current_pair(base: Scene, field: str) -> tuple:
    """The scene's value of a per-joint key as a pair (a scalar as two equal values; an
    effect the scene lacks as zeros)."""
    effect, dot, name = field.partition(".")
    current = (getattr(base, effect) or {}).get(name) if dot else getattr(base, field)
    if current is None:
        return (0.0, 0.0)
    return tuple(current) if isinstance(current, tuple) else (current, current)
