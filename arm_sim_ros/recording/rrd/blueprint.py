"""What a Rerun recording shows and where: the timeline, the series' names and colours, the
effects document, the arm's static styles, and the blueprint (the layout the viewer opens
with). The entity paths are readouts.py's; nothing here logs per step (see writer.py).

Everything follows the scene's effects (a readouts.Snapshot): a channel, a stored energy, a
winding current or a joint torque the scene does not have has no entity and no series.
"""
from __future__ import annotations

import unicodedata

import rerun as rr
import rerun.blueprint as rrb

from ...physics.effects import EffortLimits
from ...physics.scene import MAPPINGS, load_scene, preset_names
from ...physics.urdf.read import changed_values
from ..readouts import (ACCUMULATED_ERROR, COMMANDED, KINDS, LOCAL_ERROR, MEASURED, SUBSTEPS,
                        accuracy_paths, channel_path, extra_paths, reach, stored_path)

TIMELINE = "sim_time"            # steps x step_size; continued across resets, as the node's stamps
ROS_TIME = "ros_time"            # the JointState stamp of each row: stamp origin + sim_time
LOG_TIME = "log_time"            # wall clock when the recorder received the row (Rerun's log time)
TRACE_SECONDS = 2.0              # the tip trace shows this much simulated time up to the cursor
EFFECTS_PATH = "scene/effects"   # the effects document (markdown, static)

# The viewer's font lacks many glyphs (ᵀ, say) and a missing one crashes it: names and
# documents use ASCII and these, each seen drawn in a headless screenshot.
DRAWN = set("∫τ·²₀−") | {"\u0307"}

# Bright enough for the viewer's dark theme; one colour per readout wherever it appears.
ORANGE, BLUE, WHITE, VIOLET = (255, 170, 60), (90, 180, 255), (245, 245, 245), (225, 120, 255)
TOTAL = "energy/total"            # E; T and each stored part are in the books (as changes)
RESIDUAL = ("energy/balance_residual", "residual E−E₀−inputs+losses", VIOLET)
STORED = {  # part of E: (series name of its change since t = 0, colour)
    "kinetic": ("stored: kinetic T−T₀", ORANGE),
    "gravity": ("stored: gravity V−V₀", BLUE),
    "springs": ("stored: springs", (80, 225, 200)),
    "windings": ("stored: winding inductance", (235, 225, 90)),
}
CHANNELS = {  # channel: (what it integrates, colour)
    "work": ("actuator work ∫τ·q̇dt", (110, 230, 110)),
    "electrical_input": ("electrical ∫v·i dt", (170, 240, 70)),
    "payload_exchange": ("payload grasp/release", (190, 190, 255)),
    "dissipated": ("damping ∫d·q̇²dt", (255, 120, 175)),
    "copper_loss": ("copper ∫R·i²dt", (255, 70, 70)),
}
TRANSFERS = {"work": "motors' work on the joints ∫τ·q̇dt"}   # with windings
# An input is drawn wide: a loss as large as it (a held arm's copper loss) would hide it.
WIDE, NARROW = 4.5, 2.0
OTHER_COLOR = (200, 200, 200)
JOINT_SERIES = {  # path: (title, series names)
    "joints/angle": ("angle (rad)", ("q1 shoulder", "q2 elbow")),
    "joints/velocity": ("velocity (rad/s)", ("q̇1 shoulder", "q̇2 elbow")),
    "joints/torque": ("torque received (N m)", ("τ1 shoulder", "τ2 elbow")),
    "joints/current": ("winding current (A)", ("i1 shoulder", "i2 elbow")),
}
JOINT_COLORS = ((80, 220, 235), (255, 205, 70))      # shoulder cyan, elbow amber
# Small panes carry no legend (it covered their curves): a joint's series are drawn in its
# link's colour (the arm's view says which), a command darker; hovering a curve names it.
NO_LEGEND = rrb.PlotLegend(visible=False)
COMMANDED_SERIES = ("τ1 commanded", "τ2 commanded")
COMMANDED_COLORS = ((40, 130, 255), (255, 110, 40))  # beside the applied torque's cyan, amber
# With sensors the readings are drawn narrow over the truth, which is drawn wide beneath.
MEASURED_SERIES = {"joints/angle": ("q1 measured", "q2 measured"),
                   "joints/velocity": ("q̇1 measured", "q̇2 measured")}
# The node's story, one row per tick (node/recorder_link.py): (view title, series name,
# unit, colour).
NODE_SERIES = {
    "node/commands_refused": ("Refused commands / tick", "refused commands in the tick",
                              "1/tick", (255, 90, 90)),
    "node/late_ticks": ("Late ticks", "late: > 1.5 periods after the last tick", "1/tick",
                        (255, 170, 60)),
    "node/real_time_factor": ("Real-time factor", "simulated s / wall s over 0.1 s", "1",
                              (110, 230, 110)),
    "node/substeps": ("Sub-steps / tick", "RK sub-steps in the tick", "1/tick", (90, 180, 255)),
}
# The error books (readouts.accuracy_values), at the steps sampled: every step under
# recorder.step, every BOOKS_EVERY-th and each batch's last under step_batch (telemetry.py):
# (series name, colour, width).
ACCURACY_SERIES = {
    LOCAL_ERROR: ("local error estimate", (255, 170, 60), NARROW),
    ACCUMULATED_ERROR: ("accumulated error estimate", (90, 180, 255), NARROW),
    SUBSTEPS: ("sub-steps per step", (110, 230, 110), NARROW),
}
# A count over the steps since the row before (sub-steps): held back to that row, not drawn
# as a ramp between the two.
STEPPED = {path: rr.components.InterpolationMode.StepBefore
           for path in (SUBSTEPS, "node/substeps")}
UNITS = {"energy": "J", "books": "J", "joints/angle": "rad", "joints/velocity": "rad/s",
         "joints/torque": "N m", COMMANDED: "N m", "joints/current": "A",
         MEASURED["joints/angle"]: "rad", MEASURED["joints/velocity"]: "rad/s",
         "accuracy": "rad, rad/s", SUBSTEPS: "1/step"}
TRACE_COLOR = (190, 190, 190)     # neutral: violet is the residual's
HORIZON_COLOR = (100, 100, 100)
# The physics' y up into the 2D view's y down: the arm's drawing is stored as the physics has it.
FLIP = rr.Transform3D(scale=[1.0, -1.0, 1.0])


def drawable(text: str) -> str:
    """`text` with only glyphs the viewer draws: others by their compatibility form's
    drawable letters (ᵀ -> T), or '?'."""
    def glyph(c):
        if c in DRAWN or " " <= c <= "~" or c == "\n":
            return c
        plain = "".join(k for k in unicodedata.normalize("NFKD", c) if " " <= k <= "~")
        return plain or "?"
    return "".join(map(glyph, text))


def channel_name(name: str, kind: str) -> str:
    """A channel's series name: its kind, then what it integrates."""
    if kind == "transfer":
        return f"{TRANSFERS.get(name, name.replace('_', ' '))} (transfer)"
    return f"{kind}: {CHANNELS.get(name, (name.replace('_', ' '),))[0]}"


def series(snap) -> dict:
    """{entity path: (series names, colours, widths)} of every scalar readout
    readouts.channel_values computes for the scene."""
    out = {TOTAL: ((f"total E = {' + '.join(snap.parts)}",), (WHITE,), (NARROW,))}
    out[RESIDUAL[0]] = ((RESIDUAL[1],), (RESIDUAL[2],), (NARROW,))
    for part in snap.parts:
        name, color = STORED.get(part, (f"stored: {part}", OTHER_COLOR))
        if part == "kinetic" and any(snap.arm.armature):
            name += " (links and rotors)"
        out[stored_path(part)] = ((name,), (color,), (NARROW,))
    for name, kind in snap.kinds.items():
        color = CHANNELS[name][1] if name in CHANNELS else OTHER_COLOR
        out[channel_path(name, kind)] = ((channel_name(name, kind),), (color,),
                                         (WIDE if kind == "input" else NARROW,))
    for path in joint_paths(snap):
        names = joint_series(path)[1]
        wide = WIDE if snap.measured and path in MEASURED else NARROW
        out[path] = (names, JOINT_COLORS[:len(names)], (wide,) * len(names))
        if snap.measured and path in MEASURED:
            out[MEASURED[path]] = (MEASURED_SERIES[path], COMMANDED_COLORS, (NARROW, NARROW))
    if snap.commanded:
        out[COMMANDED] = (COMMANDED_SERIES, COMMANDED_COLORS, (NARROW, NARROW))
    for path in accuracy_paths(snap):
        name, color, width = ACCURACY_SERIES[path]
        out[path] = ((name,), (color,), (width,))
    return out


def node_series() -> dict:
    """{entity path: (series names, colours, widths)} of the node's per-tick story."""
    return {path: ((name,), (color,), (NARROW,))
            for path, (_, name, _, color) in NODE_SERIES.items()}


def unit(path: str) -> str:
    """The unit of an entity's values ("1": a plain number, "" if unknown)."""
    if path in NODE_SERIES:
        return NODE_SERIES[path][2]
    while path:
        if path in UNITS:
            return UNITS[path]
        path = path.rpartition("/")[0]
    return ""


def joint_paths(snap) -> list[str]:
    return (["joints/angle", "joints/velocity"] + (["joints/torque"] if snap.drives else [])
            + list(extra_paths(snap.extra)))


def joint_series(path: str):
    name = path.rpartition("/")[2]
    return JOINT_SERIES.get(path, (name, (name,)))


def books_paths(snap) -> list[str]:
    """The 'where did the energy go' view: each stored part's change, the inputs, the
    losses, and the residual (they sum to it; transfers are not in the books)."""
    kinds = snap.kinds.items()
    return ([stored_path(part) for part in snap.parts]
            + [channel_path(n, k) for kind in KINDS[:2] for n, k in kinds if k == kind]
            + [RESIDUAL[0]])


def torque_view(snap, path: str) -> rrb.TimeSeriesView:
    """A joint's view; with commands, the torque view shows the commanded beside the applied."""
    if path == "joints/torque" and snap.commanded:   # short: four such panes share a row
        return rrb.TimeSeriesView(name="Torque & command (N m)", contents=[path, COMMANDED],
                                  plot_legend=NO_LEGEND)
    if snap.measured and path in MEASURED:     # the readings drawn over the truth
        return rrb.TimeSeriesView(name=f"Joint {joint_series(path)[0]}: measured over true",
                                  contents=[path, MEASURED[path]])
    return rrb.TimeSeriesView(name=f"Joint {joint_series(path)[0]}", origin=path,
                              plot_legend=NO_LEGEND)


def node_views() -> list:
    """The node's story: one small view per per-tick series."""
    return [rrb.TimeSeriesView(name=title, origin=path, plot_legend=NO_LEGEND)
            for path, (title, _, _, _) in NODE_SERIES.items()]


def arm3d_view(arm) -> rrb.Spatial3DView:
    """The URDF arm (recording/rrd/arm3d.py), z up as in RViz (the floor grid is V = 0), seen
    from the plane's counter-clockwise side (-y), right of and above it, so the torque
    arrows along the joint axes show."""
    extent = reach(arm)
    return rrb.Spatial3DView(
        name="Arm in 3D (URDF)", origin="arm3d",      # COMs, torques along the axes, g
        eye_controls=rrb.EyeControls3D(position=(0.6 * extent, -1.35 * extent, 0.4 * extent),
                                       look_target=(0.0, 0.0, 0.0),
                                       eye_up=(0.0, 0.0, 1.0)))


TRUST = "Can I trust this run?"
OVERVIEW = "Arm, energy books, joints"


def trust_view(snap) -> rrb.Vertical:
    """One look at whether to believe the run: the energy books close (the residual, J),
    each step's local error estimate and their sum (rad, rad/s; the tolerance in the title:
    it is a scaled error per second, in no unit the estimate has), what holding them cost
    (sub-steps per step) and what the simulator did (events). Each pane scales to its own
    series: J and rad apart, a step's error apart from the sum of thousands. No legends: a
    pane holds one series, which its title names with its unit (as its name does, on hover;
    the entities' own names leave it to their `unit`, which `arm-sim inspect` appends)."""
    legend = NO_LEGEND

    def pane(title, named):
        return rrb.TimeSeriesView(
            name=title, contents=list(named), plot_legend=legend,
            overrides={path: rr.SeriesLines.from_fields(names=[drawable(name)])
                       for path, name in named.items()})
    none = "" if snap.estimated else " (no error estimate for these steps)"
    counted = SUBSTEPS in accuracy_paths(snap)    # dopri5 adapts its own step: none to count
    panes = [pane(f"Energy balance residual [J]: flat at 0 when the books close "
                  f"(E(0) = {snap.initial_energy:.6g} J){'' if counted else none}",
                  {RESIDUAL[0]: "residual E−E₀−inputs+losses [J]"})]
    if snap.estimated:
        panes += [pane(f"Local error per step [rad, rad/s]; {snap.held_by}",
                       {LOCAL_ERROR: "local error estimate [rad, rad/s]"}),
                  pane("Accumulated error [rad, rad/s]: estimate of the global error",
                       {ACCUMULATED_ERROR: "accumulated error estimate [rad, rad/s]"})]
    if counted:
        panes.append(pane(f"Sub-steps per step: what accuracy and stability cost{none}",
                          {SUBSTEPS: "sub-steps per step [1]"}))
    events = rrb.TextLogView(name="Events: sub-stepping, saturation, switches, faults",
                             origin="events")
    return rrb.Vertical(rrb.Grid(*panes, grid_columns=2), events, row_shares=[3, 1],
                        name=TRUST)


def blueprint(snap, live: bool, node: bool = False) -> rrb.Blueprint:
    """Two tabs, the trust view (trust_view) open first; then the arm, effects and events
    on the left, the energy books, the energy levels, the joints and (for the node) its
    story per tick on the right."""
    extent = reach(snap.arm)
    trace_range = rrb.VisibleTimeRanges(
        timeline=TIMELINE, start=rrb.TimeRangeBoundary.cursor_relative(seconds=-TRACE_SECONDS),
        end=rrb.TimeRangeBoundary.cursor_relative(seconds=0.0))
    # The arm is stored y up, as the physics has it; FLIP (logged at "arm") turns it for
    # the 2D view, whose y axis points down, so the bounds are in the viewer's frame.
    arm_view = rrb.Spatial2DView(
        name="Arm (y up): shoulder cyan, elbow amber", origin="/", contents=["+ arm/**"],
        visual_bounds=rrb.VisualBounds2D(x_range=[-extent, extent], y_range=[-extent, extent]),
        overrides={"arm/tip_trace": trace_range})
    legend = rrb.PlotLegend(rrb.Corner2D.LeftTop)
    books = rrb.TimeSeriesView(
        name="Where did the energy go? Books since t = 0 (J): stored + losses = inputs",
        contents=books_paths(snap), plot_legend=legend)
    transfers = [channel_path(n, k) for n, k in snap.kinds.items() if k == "transfer"]
    levels = rrb.TimeSeriesView(   # one series: its title names it, no legend over it
        name=f"Energy E = {' + '.join(snap.parts)} (J)", contents=[TOTAL] + transfers,
        plot_legend=rrb.PlotLegend(rrb.Corner2D.LeftTop) if transfers else NO_LEGEND)
    if snap.arm3d is not None:
        arm_view = rrb.Horizontal(arm_view, arm3d_view(snap.arm))
    joints = [torque_view(snap, p) for p in joint_paths(snap)]
    right = [books, levels, rrb.Horizontal(*joints)]
    if node:
        right.append(rrb.Horizontal(*node_views()))
    overview = rrb.Horizontal(
        rrb.Vertical(arm_view,
                     rrb.TextDocumentView(name="Effects the scene calls for", origin=EFFECTS_PATH),
                     rrb.TextLogView(name="Events", origin="events"),
                     row_shares=[4, 4, 2]),
        rrb.Vertical(*right, row_shares=[5, 2, 2, 2][:len(right)]),
        column_shares=[2, 3], name=OVERVIEW)
    return rrb.Blueprint(
        rrb.Tabs(trust_view(snap), overview, active_tab=0),   # the trust view opens
        rrb.TimePanel(timeline=TIMELINE, play_state="following" if live else "paused",
                      state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
    )


# --- the effects document ---------------------------------------------------------------

def _value(value) -> str:
    if isinstance(value, tuple):      # numbers, or names (a servo's interfaces)
        return ", ".join(_value(v) for v in value)
    return f"{value:g}" if isinstance(value, float) else str(value)


def _unit(unit: str) -> str:      # a table cell: choices a|b as a/b
    return "" if unit == "1" else unit.replace("^2", "²").replace("|", "/")


def effect_rows(snap, effect) -> list[tuple[str, str, str]]:
    """(parameter, value, unit) of one effect, as the scene gave them."""
    scene, name = snap.scene, effect.name
    if name in MAPPINGS:
        units = {p.name: p.unit for p in MAPPINGS[name].parameters}
        rows = [(key, _value(v), _unit(units.get(key, "")))
                for key, v in (getattr(scene, name) or {}).items() if v is not None]
        if name == "motors":
            rows.append(("armature N²J", _value(effect.armature), "kg m²"))
        return rows
    if name == "gravity":
        return [("magnitude along −y", _value(effect.gravity), "m/s²")]
    if name == "damping":
        return [("d" if not isinstance(scene.damping, tuple) else "d per joint",
                 _value(scene.damping), "N m s/rad")]
    if name == "effort_limits":
        return [("limit per joint", _value(effect.limits), _unit(EffortLimits.parameter.unit))]
    if name == "actuator":
        rows = [("policy", scene.policy, "")]
        if getattr(effect, "fixed", None) is not None:
            rows.append(("torque", _value(tuple(effect.fixed)), "N m"))
        return rows
    return []


def changed_from_preset(scene) -> list:
    """`key old -> new` for what a run changed in the preset its scene is named after (its
    description was written for the preset); none for a scene of its own."""
    if scene.name not in preset_names():
        return []
    return [change for change in changed_values(load_scene(scene.name), scene)
            if not change.startswith(("description ", "duration "))]


def effects_document(snap) -> str:
    """The effects the scene called for, with their parameters in units, and its books."""
    scene = snap.scene
    about = f": {scene.description}" if scene.description else ""
    if changed := changed_from_preset(scene):   # the preset's words may no longer hold
        about += f" (changed from the preset: {'; '.join(changed)})"
    lines = [f"**{scene.name}**{about} ({scene.method}, h = {scene.step_size:g} s)", "",
             "| effect | parameter | value | unit |", "|---|---|---|---|"]
    for effect in snap.effects:
        rows = effect_rows(snap, effect) or [("", "", "")]
        lines += [f"| {effect.name if i == 0 else ''} | {p} | {v} | {u} |"
                  for i, (p, v, u) in enumerate(rows)]
    if not snap.effects:
        lines.append("| none: the bare arm | | | |")
    units = {p.name: p.unit for p in MAPPINGS["sensors"].parameters}
    sensing = [(key, _value(v), _unit(units[key])) for key, v in (scene.sensors or {}).items()
               if v is not None] + ([("command_delay", _value(scene.command_delay), "s")]
                                    if scene.command_delay else [])
    lines += [f"| {'sensors, latency' if i == 0 else ''} | {p} | {v} | {u} |"
              for i, (p, v, u) in enumerate(sensing)]
    kinds = snap.kinds.items()
    lines += ["", "**Energy books (J)**: E(t) − E(0) = inputs − losses + residual", "",
              f"- E: {' + '.join(snap.parts)}"]
    for kind, title in (("input", "inputs"), ("loss", "losses"),
                        ("transfer", "transfers (inside the books, not counted)")):
        names = [name for name, k in kinds if k == kind]
        if names:
            lines.append(f"- {title}: {', '.join(names)}")
    if snap.extra:
        unit = " (A)" if tuple(snap.extra) == ("i1", "i2") else ""
        lines.append(f"- extra state: {', '.join(snap.extra)}{unit}")
    return drawable("\n".join(lines) + "\n")


def styles(snap, node: bool = False) -> list:
    """(entity path, [archetypes]) of what does not change from step to step, to log static:
    the series' names, colours and units, the effects document, the flip of the arm's
    drawing into the viewer's frame, the horizon, and how links, joints and trace are drawn."""
    styled = series(snap) | (node_series() if node else {})
    static = [(path, [rr.SeriesLines(names=[drawable(n) for n in names], colors=list(colors),
                                     widths=list(widths), interpolation_mode=STEPPED.get(path)),
                      rr.AnyValues(unit=unit(path))])
              for path, (names, colors, widths) in styled.items()]
    extent = reach(snap.arm)
    return static + [(path, [archetype]) for path, archetype in [
        ("arm", FLIP),
        (EFFECTS_PATH, rr.TextDocument(effects_document(snap), media_type=rr.MediaType.MARKDOWN)),
        ("arm/horizon", rr.LineStrips2D([[(-extent, 0.0), (extent, 0.0)]], colors=[HORIZON_COLOR],
                                        radii=[0.004], draw_order=0.0)),
        ("arm/links", rr.LineStrips2D.from_fields(colors=list(JOINT_COLORS), radii=[0.035],
                                                  draw_order=[20.0])),
        ("arm/joints", rr.Points2D.from_fields(colors=[(245, 245, 245)], radii=[0.05],
                                               draw_order=[30.0])),
        ("arm/tip_trace", rr.LineStrips2D.from_fields(colors=[TRACE_COLOR], radii=[0.008],
                                                      draw_order=[10.0])),
    ]]
