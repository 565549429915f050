"""What a recording logs static (the blueprint of a new layout, series styles, the scene as
recording properties, the 3D arm): logged by the recorder (telemetry.py) at a send, only
where it changed.
"""
from __future__ import annotations

import numpy as np

from .blueprint import blueprint, effects_document, styles
from .properties import send_properties
from .sinks import send_blueprint


class StaticData:
    """What a recording logs static (the blueprint, series styles, the scene as data, the
    3D arm), logged again only where it changed, and at most once a send (flush): a live
    change (100/s from a slider or a fuzzer) must not grow the file and rerun's memory by
    a mesh, or a blueprint's ~70 entries, or ~20 styles and properties, each time (rerun
    keeps ~2 kB per entry until the file closes)."""

    def __init__(self, live: bool):
        self.live = live
        self._sent = {}           # kind -> what it was last logged from

    def drawn(self, snap) -> tuple:
        """The layout of the blueprint the sinks opened with (snap's): not sent again."""
        self._sent["layout"] = snap.key
        return snap.key

    def send(self, stream, snap, sim, node: bool, stamp_origin_ns) -> None:
        with np.errstate(over="ignore"):   # rerun draws in float32: 1e200 m is drawn as inf
            self._send(stream, snap, sim, node, stamp_origin_ns)

    def _send(self, stream, snap, sim, node: bool, stamp_origin_ns) -> None:
        if self._changed("layout", snap.key):
            send_blueprint(stream, blueprint(snap, self.live, node))
        if self._changed("styles", (snap.key, effects_document(snap))):
            for path, archetypes in styles(snap, node):    # each entity's, where it changed
                if self._changed(("style", path), repr(archetypes)):
                    stream.log(path, *archetypes, static=True)
        if self._changed("properties", (sim.scene, snap.key)):   # a reset keeps them
            send_properties(stream, snap, sim, stamp_origin_ns, node)
        if snap.arm3d is not None and self._changed(
                "arm3d", (snap.arm3d, snap.arm, sim.scene.gravity, snap.drives)):
            snap.arm3d.log_static(stream, snap.arm, sim.scene.gravity, snap.drives)

    def _changed(self, kind, source) -> bool:
        if self._sent.get(kind) == source:
            return False
        self._sent[kind] = source
        return True
