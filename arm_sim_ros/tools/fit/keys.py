"""The free parameters of a fit: scene keys by their dotted names, one number each.

`damping`, `gravity`, `payload.mass`: one number (a scalar damping stays shared by both
joints). A per-joint key (`friction.coulomb`, `motors.rotor_inertia`, `springs.stiffness`,
`link_masses`, a per-joint `damping`) frees both joints' values, `key[i]` only joint i's.
Everything else keeps the base scene's value. An effect the base scene lacks is added with
its free key at a typical value (its other keys must have defaults: `motors.gear_ratio`
has none, so motors need the base scene's). Of the sensors, `sensors.delay` and
`sensors.position_offset` (and `command_delay`) are fitted, continuous (observe.py); a
scene written with them rounds the delays to whole steps, as a scene must have them.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

from ...physics.scene import FIELD_KINDS, MAPPINGS, Scene, SceneError
from .data import FitError

# Top-level keys a recording can identify, with units and check.
FIELDS = {"gravity": ("m/s^2", "non-negative"), "damping": ("N m s/rad", "non-negative"),
          "link_lengths": ("m", "positive"), "link_masses": ("kg", "positive"),
          "com_distances": ("m", "any"), "com_inertias": ("kg m^2", "non-negative"),
          "command_delay": ("s", "non-negative")}
# Effects whose keys would not change a replay of the applied torque.
NOT_FITTED = ("controller_model",)
# The sensors' keys a recording identifies: the others are noise, counts or rates.
FITTED_SENSORS = ("delay", "position_offset")
# A typical magnitude per key: where a start at 0 is moved to, and the scale of the search.
TYPICAL = {"damping": 0.1, "friction.coulomb": 0.1, "friction.static": 0.1,
           "friction.stribeck_velocity": 0.05, "motors.rotor_inertia": 1e-5,
           "motors.gear_ratio": 10.0, "payload.mass": 0.1, "springs.stiffness": 1.0,
           "sensors.delay": 1e-3, "sensors.position_offset": 1e-2, "command_delay": 1e-3}
KEY = re.compile(r"^([a-z_]+)(?:\.([a-z_]+))?(?:\[([01])\])?$")


@dataclass(frozen=True)
class FreeParameter:
    """One number of the scene: `field` (a Scene field), `name` (the effect's key, or None),
    `index` (the joint of a per-joint key, or None)."""

    field: str
    name: str | None
    index: int | None
    unit: str
    lower: float          # 0 for a quantity that cannot be negative, else -inf
    typical: float

    @property
    def key(self) -> str:
        dotted = self.field + (f".{self.name}" if self.name else "")
        return dotted + (f"[{self.index}]" if self.index is not None else "")

    def value(self, scene: Scene) -> float:
        current = getattr(scene, self.field)
        if self.name is not None:
            current = (current or {}).get(self.name)
            if current is None and self.name == "static" and scene.friction:
                current = scene.friction["coulomb"]      # absent: breakaway = coulomb
        if current is None:
            return 0.0
        if isinstance(current, tuple):
            return current[self.index if self.index is not None else 0]
        return current


def parse_free(text: str, scene: Scene) -> list[FreeParameter]:
    """`--free KEY[,KEY...]` as FreeParameters (a per-joint key without [i]: both joints)."""
    keys = [k.strip() for k in text.split(",") if k.strip()]
    if not keys:
        raise FitError("--free needs at least one scene key, e.g. --free damping,payload.mass")
    free = [p for key in keys for p in _parameters(key, scene)]
    seen = {}
    for p in free:
        if p.key in seen:
            raise FitError(f"--free names {p.key} twice")
        whole = seen.get((p.field, p.name))      # a scalar key and one of its joints
        if whole is not None and (whole.index is None) != (p.index is None):
            raise FitError(f"--free names {whole.key} and {p.key}: the same number twice")
        seen[p.key] = seen[(p.field, p.name)] = p
    return free


def _parameters(key: str, scene: Scene) -> list[FreeParameter]:
    match = KEY.match(key)
    field, name, index = match.groups() if match else (key, None, None)
    if not match or field not in FIELD_KINDS:
        raise FitError(f"--free {key}: not a scene key; free keys are "
                       f"{', '.join(FIELDS)} and effect keys such as friction.coulomb")
    index = None if index is None else int(index)
    if name is None:
        if field not in FIELDS:
            raise FitError(f"--free {key}: not a physical parameter a recording identifies; "
                           f"top-level keys that are: {', '.join(FIELDS)}")
        unit, check = FIELDS[field]
        per_joint = FIELD_KINDS[field] == "pair" or (field == "damping"
                                                     and isinstance(scene.damping, tuple))
    else:
        effect = MAPPINGS.get(field)
        known = {p.name: p for p in effect.parameters if field != "sensors"
                 or p.name in FITTED_SENSORS} if effect else {}
        if field in NOT_FITTED or name not in known:
            raise FitError(f"--free {key}: not a key a fit can free"
                           + (f"; {field} keys: {', '.join(known)}" if known and field not in
                              NOT_FITTED else ""))
        parameter = known[name]
        unit, check, per_joint = parameter.unit, parameter.check, parameter.kind == "pair"
    if index is not None and not (per_joint or field == "damping"):
        raise FitError(f"--free {key}: {key.partition('[')[0]} is one number, not one per joint")
    dotted = key.partition("[")[0]
    typical = TYPICAL.get(dotted, 1.0)
    lower = float("-inf") if check == "any" else 0.0
    make = lambda i: FreeParameter(field, name, i, unit, lower, typical)  # noqa: E731
    if index is not None:
        return [make(index)]
    return [make(0), make(1)] if per_joint else [make(None)]


def start_values(free, scene: Scene) -> list[float]:
    """Where a fit starts: the base scene's values, a typical one where that is 0."""
    return [p.value(scene) or p.typical for p in free]


def with_values(scene: Scene, free, values) -> Scene:
    """`scene` with the free parameters set to `values` (SceneError if impossible)."""
    overrides = {}
    for p, v in zip(free, values):
        key = p.field + (f".{p.name}" if p.name else "")
        if p.index is None:
            overrides[key] = float(v)
            continue
        pair = overrides.get(key) or list(_pair(scene, p))
        pair[p.index] = float(v)
        overrides[key] = pair
    overrides = _breakaway(scene, overrides)
    for key in ("sensors.delay", "command_delay"):     # a scene's delays are whole steps
        if key in overrides:
            overrides[key] = round(overrides[key] / scene.step_size) * scene.step_size
    return scene.replace(**{k: tuple(v) if isinstance(v, list) else v
                            for k, v in overrides.items()})


def _breakaway(scene: Scene, overrides: dict) -> dict:
    """Fs >= Fc: a breakaway friction below the Coulomb friction (fixed, or fitted and
    passing it) acts as the Coulomb friction, so a fit can move either freely."""
    friction = scene.friction or {}
    coulomb = overrides.get("friction.coulomb", friction.get("coulomb"))
    static = overrides.get("friction.static", friction.get("static"))
    if coulomb is None or static is None:
        return overrides
    return overrides | {"friction.static": [max(s, c) for s, c in zip(static, coulomb)]}


def _pair(scene: Scene, p: FreeParameter) -> tuple:
    """The current pair behind a per-joint parameter (a scalar damping as two equal values)."""
    return tuple(FreeParameter(p.field, p.name, i, p.unit, p.lower, p.typical).value(scene)
                 for i in (0, 1))


def check_free(scene: Scene, free) -> Scene:
    """The scene at the start values, or FitError saying why the keys cannot be freed."""
    try:
        return with_values(scene, free, start_values(free, scene))
    except SceneError as error:
        raise FitError(f"--free {','.join(p.key for p in free)}: {error}") from None
