"""The scene as data in a Rerun recording: its parameters, its effects and the integrator's
settings, stored as recording properties (rr.send_property, 0.41), so a recording says what
it recorded without the YAML it came from. Read back with readback.properties().

    scene        every field of the Scene (numbers as numbers, tables as JSON text)
    integrator   the Butcher tableau (c, a row by row, b), its order, the step and sub-steps
    effects      the effects the scene calls for, in assembly order
    effect.<e>   one effect's parameters: parameter, value and unit, as the effects document
    estimate     what the run computes of its own error: mode (global, off) and its meaning
    clock        the timelines and how they relate: ros_time = stamp_origin_ns + sim_time
    units        each series' entity path and unit
"""
from __future__ import annotations

import dataclasses
import json

import rerun as rr

from ...physics.stepping.integrators import INTEGRATORS
from ...physics.trust.unestimated import NO_ESTIMATE
from .blueprint import LOG_TIME, ROS_TIME, TIMELINE, effect_rows, node_series, series, unit


def _field(value):
    """A scene field as AnyValues takes it: numbers, text, lists of numbers; else JSON."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, (int, float, str)):
        return value
    if isinstance(value, (tuple, list)) and all(isinstance(v, (int, float)) for v in value):
        return [float(v) for v in value]
    return json.dumps(value, sort_keys=True, default=str)


def scene_values(scene) -> dict:
    """{field: value} of every field of the scene that is set (None fields are left out)."""
    return {f.name: _field(getattr(scene, f.name)) for f in dataclasses.fields(scene)
            if getattr(scene, f.name) is not None}


def integrator_values(sim) -> dict:
    tableau = INTEGRATORS[sim.scene.method]
    values = {"name": tableau.name, "order": tableau.order, "stages": len(tableau.c),
              "c": [float(v) for v in tableau.c], "b": [float(v) for v in tableau.b],
              "a": json.dumps([list(map(float, row)) for row in tableau.a]),
              "step_size": float(sim.step_size), "substeps_per_step": int(sim.substeps)}
    if tableau.embedded_b is not None:
        values |= {"embedded_order": tableau.embedded_order, "rtol": float(sim.scene.rtol),
                   "atol": float(sim.scene.atol)}
    return values


MEANINGS = {"off": NO_ESTIMATE + ": no shadow, no local error checks",
            "global": "the global error estimate: a shadow beside every step, the local error "
                      "measured on a schedule (accuracy/* series)"}


def estimate_values(modes) -> dict:
    """What the run computed of its own error (scene key estimate), said in words: `modes`
    in the order they ran (a node's live switch: each from the restart the events name)."""
    if len(modes) == 1:
        return {"mode": modes[0], "meaning": MEANINGS[modes[0]]}
    spans = "; then ".join(f"{mode}: {MEANINGS[mode]}" for mode in modes)
    return {"mode": ", then ".join(modes),
            "meaning": f"switched while recording (each from the restart the events name): "
                       f"{spans}"}


def properties(snap, sim, stamp_origin_ns: int | None, node: bool = False) -> list:
    """(name, rr.AnyValues) of each recording property of a run of `sim` (`snap`: its
    readouts.Snapshot)."""
    out = [("scene", rr.AnyValues(**scene_values(sim.scene))),
           ("integrator", rr.AnyValues(**integrator_values(sim))),
           ("effects", rr.AnyValues(names=[e.name for e in snap.effects] or [""]))]
    for effect in snap.effects:
        rows = effect_rows(snap, effect)
        if rows:
            parameter, value, unit_ = (list(column) for column in zip(*rows))
            out.append((f"effect.{effect.name}",
                        rr.AnyValues(parameter=parameter, value=value, unit=unit_)))
    out.append(("estimate", rr.AnyValues(**estimate_values(snap.modes))))
    clock = {"timelines": [TIMELINE, LOG_TIME] + ([ROS_TIME] if stamp_origin_ns is not None
                                                  else []),
             "source": "node" if node else "arm-sim run"}
    if stamp_origin_ns is not None:
        clock |= {"stamp_origin_ns": int(stamp_origin_ns),
                  "ros_time": "stamp_origin_ns + sim_time: each row's JointState stamp"}
    out.append(("clock", rr.AnyValues(**clock)))
    paths = list(series(snap)) + (list(node_series()) if node else [])
    out.append(("units", rr.AnyValues(path=paths, unit=[unit(p) for p in paths])))
    return out


def send_properties(stream, snap, sim, stamp_origin_ns: int | None, node: bool = False) -> None:
    """Send (or replace: a property is static) every property of the run on `stream`."""
    for name, values in properties(snap, sim, stamp_origin_ns, node):
        stream.send_property(name, values)
