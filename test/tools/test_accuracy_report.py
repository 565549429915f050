"""The work-precision diagram reads at any size: the title and the whole legend inside the
picture, one colour and marker per integrator or peer in every plot, tolerance labels that do
not overlap, and every guide line in the legend."""
from itertools import combinations

import matplotlib
import pytest

matplotlib.use("Agg")
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from arm_sim_ros.tools.accuracy import report as report  # noqa: E402


def run(series, kind, h, error, cpu, tolerance=None, integrator=None):
    peer = kind.startswith("mujoco")
    return {"series": series, "kind": kind, "integrator": integrator or series, "step_size": h,
            "tolerance": tolerance, "max_state_error": error, "cpu_s_per_sim_s": cpu,
            "estimate": None if peer else "global", "path": "mj_step" if peer else "python"}


def result(scene, floor=None, crowded=False):
    runs = [run(name, "method", h, 10 ** (-k - shift), 1e-4 * 2 ** k)
            for name, shift in (("rk4", 4), ("semi_implicit_euler", 0), ("dopri5", 6))
            for k, h in enumerate((0.02, 0.01, 0.005, 0.0025))]
    runs += [run(f"mujoco {name}", "mujoco", h, 10 ** (-k - shift), 3e-4 * 2 ** k)
             for name, shift in (("Euler", 0), ("RK4", 3)) for k, h in enumerate((0.02, 0.01))]
    runs.append(run("rk4 (scene as set)", "as set", 0.01, 5e-5, 2e-4, 5e-5, "rk4"))
    # a tolerance sweep whose points crowd together, as the looser tolerances do
    spread = 1.02 if crowded else 2.0
    runs += [run("rk4 + tolerance", "tolerance", 0.01, 10 ** -(3 + k * (0.05 if crowded else 1)),
                 2e-4 * spread ** k, 10.0 ** -(2 + k), "rk4") for k in range(8)]
    return {"scene": scene, "duration": 2.0, "runs": runs, "path": "python",
            "peers": {"mujoco": {"floor": floor}} if floor else {}}


def renderer_of(fig):
    """The figure laid out and drawn again (plot() closed it), for its artists' boxes."""
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    return renderer


@pytest.fixture
def drawn(monkeypatch, tmp_path):
    """plot() -> (the figure as saved, the saved picture's size in pixels)."""
    saved = []
    original = Figure.savefig

    def keep(fig, path, **options):
        saved.append((fig, options))
        return original(fig, path, **options)
    monkeypatch.setattr(Figure, "savefig", keep)

    def draw(results):
        path = tmp_path / f"plot{len(saved)}.png"
        report.plot(results, str(path))
        fig, options = saved[-1]
        return fig, options, path
    return draw


@pytest.mark.parametrize("scenes", [1, 2, 5])
def test_the_title_and_every_legend_entry_are_inside_the_saved_picture(drawn, scenes):
    results = [result(f"scene{i}", floor=0.3 if i == 0 else None) for i in range(scenes)]
    fig, options, path = drawn(results)
    (legend,) = fig.legends
    labels = [t.get_text() for t in legend.get_texts()]
    assert labels == report.legend_labels(results)      # every series, each once
    assert report.TARGET_LABEL in labels and report.FLOOR_LABEL in labels   # guide lines too
    # the saved picture is the tight box around every artist: title and legend included
    assert options.get("bbox_inches") == "tight"
    renderer = renderer_of(fig)
    panels = [ax.get_window_extent(renderer) for ax in fig.axes if ax.axison]
    legend_box = legend.get_window_extent(renderer)
    title_box = fig._suptitle.get_window_extent(renderer)
    assert all(legend_box.y1 <= p.y0 for p in panels)   # below the panels, not over them
    assert all(title_box.y0 >= p.y1 for p in panels)    # above them
    assert path.stat().st_size > 0


def test_each_series_keeps_its_colour_and_marker_whatever_else_is_plotted():
    alone = report._style("semi_implicit_euler", "method")
    assert alone == report._style("semi_implicit_euler", "method")
    styles = {name: report._style(name, "method") for name in
              ("euler", "semi_implicit_euler", "midpoint", "rk4", "rk38", "dopri5")}
    styles |= {name: report._style(name, "mujoco") for name in
               ("mujoco Euler", "mujoco implicit", "mujoco implicitfast", "mujoco RK4")}
    pairs = [(s["color"], s["marker"]) for s in styles.values()]
    assert len(set(pairs)) == len(pairs)                 # no two share colour and marker
    assert len({s["color"] for s in styles.values()}) == len(styles)
    assert report._style("unknown method", "method") == report._style("unknown method", "method")


def test_tolerance_labels_never_overlap(drawn):
    fig, _, _ = drawn([result("crowded", crowded=True)])
    renderer = renderer_of(fig)
    (ax,) = [ax for ax in fig.axes if ax.axison]
    boxes = [t.get_window_extent(renderer) for t in ax.texts]
    assert 1 <= len(boxes) < 8                           # crowded points share one label
    assert not any(a.overlaps(b) for a, b in combinations(boxes, 2))


def test_the_title_names_mujoco_only_where_it_ran():
    alone = result("alone")
    alone["runs"] = [r for r in alone["runs"] if r["estimate"] is not None]
    assert report.title_of([result("both"), alone]).endswith("ours and MuJoCo on the same scenes")
    assert report.title_of([alone]).endswith("CPU time, ours")


def test_every_tolerance_label_stays_inside_its_panel(drawn):
    """Alone, the tolerance sweep spans the panel from its top left corner to its bottom right
    one: the labels there go below and to the left of their points (the last was cut at the
    right edge)."""
    alone = result("alone")
    alone["runs"] = [r for r in alone["runs"] if r["kind"] == "tolerance"]
    fig, _, _ = drawn([alone])
    renderer = renderer_of(fig)
    (ax,) = [ax for ax in fig.axes if ax.axison]
    inside = ax.get_window_extent(renderer)
    boxes = [t.get_window_extent(renderer) for t in ax.texts]
    assert len(boxes) == 8
    assert all(inside.x0 <= b.x0 and b.x1 <= inside.x1 and inside.y0 <= b.y0 and b.y1 <= inside.y1
               for b in boxes), [(b.x1, b.y1) for b in boxes] + [(inside.x1, inside.y1)]


def test_a_series_without_the_estimate_keeps_its_colour_dotted_and_hollow():
    """The estimate's price reads as the gap between two lines of one colour; MuJoCo's two
    ways of stepping likewise."""
    on, off = report._style("rk4", "method", "global"), report._style("rk4, estimate off",
                                                                      "method", "off")
    stepped, rolled = (report._style("mujoco RK4", "mujoco", None),
                       report._style("mujoco RK4 rollout", "mujoco rollout", None))
    for solid, hollow, lines in ((on, off, ("-", ":")), (stepped, rolled, ("--", "-."))):
        assert (solid["color"], solid["marker"]) == (hollow["color"], hollow["marker"])
        assert (solid["linestyle"], hollow["linestyle"]) == lines
        assert "markerfacecolor" not in solid and hollow["markerfacecolor"] == "white"


def test_tick_labels_never_run_into_each_other(drawn):
    """Costs from 2e3 to 6e4 µs: matplotlib labels minor ticks too there (3x10^4 ran into
    4x10^4); the decades alone are labelled."""
    narrow = result("narrow")
    narrow["runs"] = [run("rk4", "method", h, 10.0 ** -k, 2e-3 * 30 ** (k / 3))
                      for k, h in enumerate((0.02, 0.01, 0.005, 0.0025))]
    fig, _, _ = drawn([narrow])
    renderer = renderer_of(fig)
    (ax,) = [ax for ax in fig.axes if ax.axison]
    for axis in (ax.xaxis, ax.yaxis):
        boxes = [t.get_window_extent(renderer) for t in axis.get_ticklabels(which="both")
                 if t.get_visible() and t.get_text()]
        assert len(boxes) >= 2
        assert not any(a.overlaps(b) for a, b in combinations(boxes, 2))
