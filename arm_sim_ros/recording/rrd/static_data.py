"""What a recording logs static (the blueprint of a new layout, series styles, the scene as
recording properties, the 3D arm): logged by the recorder (telemetry.py) at a send, only
where it changed.
"""
from __future__ import annotations

import time

import numpy as np

from .blueprint import blueprint, effects_document, styles
from .properties import send_properties
from .sinks import send_blueprint

STATIC_PERIOD = 10.0    # wall seconds between static logs of a changed setup (at most)...
LIVE_STATIC_PERIOD = 1.0   # ...and to a viewer, which a person is watching


class StaticData:
    """What a recording logs static (the blueprint, series styles, the scene as data, the
    3D arm), logged again only where it changed, and at most once a send (flush): a live
    change (100/s from a slider or a fuzzer) must not grow the file and rerun's memory by
    a mesh, or a blueprint's ~70 entries, or ~20 styles and properties, each time (rerun
    keeps ~2 kB per entry until the file closes). A setup that changes what they show
    (a restart's new E(0) is in a pane's title) waits STATIC_PERIOD after the last one, so
    sets at any rate cost a bounded ~1.4 kB/s; the file's close sends the latest."""

    def __init__(self, live: bool):
        self.live = live
        self.due = None           # (snap, sim) whose static data is logged when next sent
        self._sent = {}           # kind -> what it was last logged from
        self._sent_at = None      # time.monotonic() of the last static logs
        self._period = LIVE_STATIC_PERIOD if live else STATIC_PERIOD

    def drawn(self, snap) -> tuple:
        """The layout of the blueprint the sinks opened with (snap's): not sent again."""
        self._sent["layout"] = snap.key
        return snap.key

    def send(self, stream, node: bool, stamp_origin_ns, force: bool = False) -> None:
        """Log the due setup's static data where it changed: at once the first time and
        when forced (the file closes), else once its period has passed since the last."""
        now = time.monotonic()
        if self.due is None or not (force or self._sent_at is None
                                    or now - self._sent_at >= self._period):
            return
        (snap, sim), self.due, self._sent_at = self.due, None, now
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
