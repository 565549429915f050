"""What a Rerun recording shows and where: the timeline, the entity path of each channel,
the series' names and colours, the arm's static styles, and the blueprint (the layout the
viewer opens with). Nothing here logs per step; see writer.py for that.

Channels follow the scene's effects (Simulator.channels): no `energy/dissipated`
without damping, no `work/actuator` or joint torques without an actuator.
"""
from __future__ import annotations

import rerun as rr
import rerun.blueprint as rrb

TIMELINE = "sim_time"            # steps x step_size; continued across resets, as the node's stamps
TRACE_SECONDS = 2.0              # the tip trace shows this much simulated time up to the cursor

# Bright enough for the viewer's dark theme; one colour per readout wherever it appears.
# Names use only glyphs the viewer's font has (a missing one, e.g. ᵀ, crashes the viewer).
ENERGY_SERIES = {
    "energy/kinetic": ("kinetic T", (255, 170, 60)),
    "energy/potential": ("potential V", (90, 180, 255)),
    "energy/total": ("total E = T + V", (245, 245, 245)),
    "energy/dissipated": ("dissipated ∫d|q̇|²dt", (255, 95, 125)),
    "work/actuator": ("actuator work ∫τ·q̇dt", (110, 230, 110)),
    "energy/balance_residual": ("residual E−E₀−W+dissipated", (225, 120, 255)),
}
JOINT_SERIES = {
    "joints/angle": ("angle (rad)", ("q1 shoulder", "q2 elbow")),
    "joints/velocity": ("velocity (rad/s)", ("q̇1 shoulder", "q̇2 elbow")),
    "joints/torque": ("applied torque (N m)", ("τ1 shoulder", "τ2 elbow")),
}
JOINT_COLORS = ((80, 220, 235), (255, 205, 70))      # shoulder cyan, elbow amber
TRACE_COLOR = (190, 190, 190)     # neutral: violet is the residual's
HORIZON_COLOR = (100, 100, 100)


def energy_paths(channels) -> list[str]:
    """The scalar channels a scene with these integrated channels produces."""
    paths = ["energy/kinetic", "energy/potential", "energy/total"]
    if "dissipated" in channels:
        paths.append("energy/dissipated")
    if "work" in channels:
        paths.append("work/actuator")
    return paths + ["energy/balance_residual"]


def joint_paths(channels) -> list[str]:
    return ["joints/angle", "joints/velocity"] + (["joints/torque"] if "work" in channels else [])


def reach(arm) -> float:
    """Half the width of the arm's view: a little more than the arm at full stretch."""
    return 1.1 * sum(arm.link_lengths)


def blueprint(arm, channels, live: bool) -> rrb.Blueprint:
    """Arm and events on the left; energy, work with residual, and joints on the right."""
    extent = reach(arm)
    energy = [p for p in ("energy/kinetic", "energy/potential", "energy/total", "energy/dissipated")
              if p in energy_paths(channels)]
    balance = [p for p in ("work/actuator", "energy/dissipated", "energy/balance_residual")
               if p in energy_paths(channels)]
    trace_range = rrb.VisibleTimeRanges(
        timeline=TIMELINE, start=rrb.TimeRangeBoundary.cursor_relative(seconds=-TRACE_SECONDS),
        end=rrb.TimeRangeBoundary.cursor_relative(seconds=0.0))
    arm_view = rrb.Spatial2DView(
        name="Arm (y up, V = 0 on the grey line)", origin="arm",
        visual_bounds=rrb.VisualBounds2D(x_range=[-extent, extent], y_range=[-extent, extent]),
        overrides={"arm/tip_trace": trace_range})
    plots = [rrb.TimeSeriesView(name="Energy (J)", contents=energy,
                                plot_legend=rrb.PlotLegend(rrb.Corner2D.LeftTop)),
             rrb.TimeSeriesView(name="Work, dissipation and balance residual (J)", contents=balance,
                                plot_legend=rrb.PlotLegend(rrb.Corner2D.LeftTop))]
    joints = [rrb.TimeSeriesView(name=f"Joint {JOINT_SERIES[p][0]}", origin=p)
              for p in joint_paths(channels)]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(arm_view, rrb.TextLogView(name="Events", origin="events"),
                         row_shares=[4, 1]),
            rrb.Vertical(*plots, rrb.Horizontal(*joints), row_shares=[3, 3, 2]),
            column_shares=[2, 3]),
        rrb.TimePanel(timeline=TIMELINE, play_state="following" if live else "paused",
                      state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
    )


def styles(arm, channels) -> list:
    """(entity path, archetype) of what does not change from step to step, to log static:
    the series' names and colours, the horizon, and how links, joints and trace are drawn."""
    static = [(path, rr.SeriesLines(names=[ENERGY_SERIES[path][0]],
                                    colors=[ENERGY_SERIES[path][1]], widths=[2.0]))
              for path in energy_paths(channels)]
    static += [(path, rr.SeriesLines(names=list(JOINT_SERIES[path][1]), colors=list(JOINT_COLORS),
                                     widths=[2.0, 2.0]))
               for path in joint_paths(channels)]
    extent = reach(arm)
    return static + [
        ("arm/horizon", rr.LineStrips2D([[(-extent, 0.0), (extent, 0.0)]], colors=[HORIZON_COLOR],
                                        radii=[0.004], draw_order=0.0)),
        ("arm/links", rr.LineStrips2D.from_fields(colors=list(JOINT_COLORS), radii=[0.035],
                                                  draw_order=[20.0])),
        ("arm/joints", rr.Points2D.from_fields(colors=[(245, 245, 245)], radii=[0.05],
                                               draw_order=[30.0])),
        ("arm/tip_trace", rr.LineStrips2D.from_fields(colors=[TRACE_COLOR], radii=[0.008],
                                                      draw_order=[10.0])),
    ]
