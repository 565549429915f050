"""`--vary KEY=SPEC`: a scene key a sweep varies and the values it takes (the guide,
docs/guides/sweeps.md, states the syntax once; this is its one reading).

A grid's values (a list, `lin:`, `log:`, `range:`) are fixed when the sweep is planned;
a distribution's (`uniform:`, `normal:`, `lognormal:`, `integers:`) are drawn per sample
from that sample's own generator (plan.py). Every value is read as `--set` reads it
(physics/scene.py parse_value: degrees as `90deg`, pairs as `1,0`, "did you mean"), so a
key or value --set refuses is refused here in the same words.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from math import isfinite

import numpy as np

from ...physics.scene import FIELD_KINDS, MAPPINGS, SceneError, parse_value

KEY = re.compile(r"^(?P<key>[A-Za-z_][\w.]*)(?:\[(?P<joint>[01])\])?$")
GRIDS = ("lin", "log", "range")
DISTRIBUTIONS = ("uniform", "normal", "lognormal", "integers")
WHOLE = ("range", "integers")      # the SPECs of whole numbers
MAX_GRID = 100_000            # values one grid key may take
PAIR_KINDS = ("pair", "float_or_pair", "pair_or_none")
# keys whose one value may itself hold commas: a list of them is separated by ';'
COMMA_KINDS = PAIR_KINDS + ("names",)


def kind_of(key: str) -> str:
    """The kind of a scene key as --set reads it ("float", "pair", "str" ...), or
    SceneError in --set's own words (unknown key, did you mean, a whole effect)."""
    effect, dot, name = key.partition(".")
    if dot and effect in MAPPINGS:
        known = {p.name: p.kind for p in MAPPINGS[effect].parameters}
        if name in known:
            return known[name]
    elif FIELD_KINDS.get(key, "effect") != "effect":
        return FIELD_KINDS[key]
    parse_value(key, "0")      # raises: an unknown key, or a whole effect's mapping
    raise SceneError(f"{key} cannot be varied")      # (parse_value always raised above)


@dataclass(frozen=True)
class Vary:
    """One `--vary`: `key` as given (`friction.coulomb[1]`), `field` the scene key it sets
    (`friction.coulomb`), `joint` the one joint it sets (None: the whole value), and either
    `values` (a grid) or `law` (name, parameters) of a distribution."""

    text: str
    key: str
    field: str
    joint: int | None
    values: tuple = ()
    law: tuple = ()

    @property
    def drawn(self) -> bool:
        return bool(self.law)

    @property
    def columns(self) -> tuple:
        """The table's columns for this key: one per joint where its values are pairs."""
        if self.values and isinstance(self.values[0], tuple):
            return (f"{self.key}[0]", f"{self.key}[1]")
        return (self.key,)

    def cells(self, value) -> tuple:
        return tuple(value) if isinstance(value, tuple) else (value,)

    def draw(self, rng: np.random.Generator):
        """This key's value for one sample, from the sample's generator."""
        name, (a, b) = self.law
        if name == "uniform":
            return float(rng.uniform(a, b))
        if name == "normal":
            return float(rng.normal(a, b))
        if name == "lognormal":
            return float(a * np.exp(b * rng.standard_normal()))
        return int(rng.integers(a, b, endpoint=True))          # integers


def parse_vary(text: str) -> Vary:
    """`KEY=SPEC` as a Vary, or SceneError (one line, naming the --vary)."""
    key_text, sep, spec = text.partition("=")
    key_text, spec = key_text.strip(), spec.strip()
    try:
        if not sep or not key_text or not spec:
            raise SceneError("not of the form KEY=SPEC (e.g. payload.mass=0.2,0.5,1.0)")
        match = KEY.match(key_text)
        if not match:
            raise SceneError(f"{key_text!r} is not a scene key (KEY, or KEY[0] / KEY[1] for "
                             "one joint of a per-joint key)")
        field, joint = match["key"], None if match["joint"] is None else int(match["joint"])
        kind = kind_of(field)
        if joint is not None and kind not in PAIR_KINDS:
            raise SceneError(f"{field} is not a per-joint key: vary it as {field}")
        head, colon, rest = spec.partition(":")
        if colon and head in GRIDS + DISTRIBUTIONS:
            whole = kind == "int"      # a seed, a count: whole numbers only
            if kind not in ("float", "int") + PAIR_KINDS or whole and head not in WHOLE:
                raise SceneError(f"{field} takes {'a name' if kind in ('str', 'choice') else kind}"
                                 f" values: give them as a list (a,b or a;b)"
                                 f"{', range: or integers:' if whole else ''}, not {head}:")
            numbers = [_endpoint(field, joint, part) for part in rest.split(":")]
            if head in GRIDS:
                return Vary(text, key_text, field, joint, values=_grid(head, numbers))
            return Vary(text, key_text, field, joint, law=_law(head, numbers))
        if colon and re.fullmatch(r"[a-z]+", head):
            raise SceneError(f"{head}: is no SPEC; grids: {', '.join(GRIDS)}; distributions: "
                             f"{', '.join(DISTRIBUTIONS)} (or a list of values)")
        separator = ";" if ";" in spec or kind in COMMA_KINDS and joint is None else ","
        items = [item.strip() for item in spec.split(separator)]
        if not all(items):
            raise SceneError(f"an empty value in the list {spec!r}")
        values = [_value(field, joint, kind, item) for item in items]
        if any(isinstance(v, tuple) for v in values):      # pairs: one number is both joints'
            values = [v if isinstance(v, tuple) else (v, v) for v in values]
        return Vary(text, key_text, field, joint, values=tuple(values))
    except SceneError as error:
        raise SceneError(f"--vary {text}: {error}") from None


def _value(field: str, joint, kind: str, item: str):
    """One list value as --set reads it; a per-joint key's one number stands for both
    joints (or for the one joint named)."""
    value = parse_value(field, item)
    if kind in PAIR_KINDS and isinstance(value, tuple) and len(value) == 1:
        value = value[0]
    if joint is not None and not _is_number(value):
        raise SceneError(f"{field}[{joint}] takes one number, got {item!r}")
    return _whole(item, value)


def _endpoint(field: str, joint, text: str):
    """A grid's or a distribution's number, read as --set reads the key's numbers."""
    if not text.strip():
        raise SceneError("an empty number in the SPEC")
    value = parse_value(field, text)
    value = value[0] if isinstance(value, tuple) and len(value) == 1 else value
    if not _is_number(value):
        raise SceneError(f"{text!r} is not one number")
    return _whole(text, value)


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _whole(text: str, value):
    """A number written as a whole number stays exact (a seed up to 2^63 - 1 has more
    digits than a double); any other, as --set read it."""
    return int(text) if re.fullmatch(r"[+-]?\d+", text.strip()) else value


def _grid(name: str, numbers: list) -> tuple:
    if name == "range":
        if len(numbers) not in (2, 3) or not all(v % 1 == 0 for v in numbers):
            raise SceneError("range:A:B[:STEP] takes whole numbers: A, A+STEP, ... below B")
        start, stop, step = (int(v) for v in numbers + [1] * (3 - len(numbers)))
        if step == 0:
            raise SceneError("range:A:B:STEP needs a STEP other than 0")
        values = range(start, stop, step)
        if not 1 <= len(values) <= MAX_GRID:
            raise SceneError(f"range:{start}:{stop}:{step} holds {len(values)} values; "
                             f"give 1 to {MAX_GRID}")
        return tuple(values)
    if len(numbers) != 3 or numbers[2] % 1 or not 1 <= numbers[2] <= MAX_GRID:
        raise SceneError(f"{name}:A:B:N takes two numbers and a count N from 1 to {MAX_GRID}")
    a, b, count = numbers[0], numbers[1], int(numbers[2])
    if name == "log":
        if not (a > 0 and b > 0 or a < 0 and b < 0):
            raise SceneError("log:A:B:N needs A and B of one sign, neither 0")
        return tuple(float(v) for v in np.geomspace(a, b, count))
    return tuple(float(v) for v in np.linspace(a, b, count))


def _law(name: str, numbers: list) -> tuple:
    if len(numbers) != 2:
        raise SceneError(f"{name}: takes two numbers ({LAWS[name]})")
    a, b = numbers
    if name in ("uniform", "integers") and not a <= b:
        raise SceneError(f"{name}:A:B needs A <= B")
    if name in ("normal", "lognormal") and not b >= 0:
        raise SceneError(f"{name}: its spread {b:g} must not be negative")
    if name == "lognormal" and not a > 0:
        raise SceneError(f"lognormal:MEDIAN:S needs a positive MEDIAN, got {a:g}")
    if name == "integers":
        if a % 1 or b % 1 or not (-2 ** 63 <= a and b < 2 ** 63):
            raise SceneError("integers:A:B takes whole numbers within 64 bits")
        return name, (int(a), int(b))
    if not all(isfinite(v) for v in numbers):
        raise SceneError(f"{name}: takes finite numbers")
    return name, (a, b)


LAWS = {"uniform": "uniform:A:B, from A to B", "normal": "normal:MEAN:SD",
        "lognormal": "lognormal:MEDIAN:S, S the spread of ln x",
        "integers": "integers:A:B, whole numbers A to B"}
