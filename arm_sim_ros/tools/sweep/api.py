"""`arm_sim_ros.sweep(...)`: the sweep `arm-sim sweep` runs, from Python."""
from __future__ import annotations

from collections.abc import Mapping

from ...physics.scene import Scene, SceneError, load_scene
from .plan import Plan, overrides
from .rows import check_metrics
from .run import SweepResult, Sweep, execute
from .spec import parse_vary


def make_sweep(base: Scene, vary, samples=None, seed: int = 0, metrics=None,
               after: float = 0.0, duration=None, estimate: str | None = "off") -> Sweep:
    """The Sweep, every key and value checked up front (SceneError: one line). `estimate`
    "off" (a sweep's default: the steps alone) unless None (the scene's own) or another;
    a --vary of estimate or tolerance sets it per sample."""
    texts = [f"{k}={v}" for k, v in vary.items()] if isinstance(vary, Mapping) else list(vary)
    varies = [parse_vary(text) for text in texts]
    plan = Plan.make(varies, samples, seed)
    if estimate is not None and not {"estimate", "tolerance"} & {v.field for v in varies}:
        base = base.replace(estimate=estimate)
    duration = base.duration if duration is None else duration
    if not isinstance(duration, (int, float)) or isinstance(duration, bool):
        raise SceneError(f"--duration {duration!r} must be a number of seconds")
    base = base.replace(duration=float(duration))
    base.steps_for(base.duration)
    if not after >= 0:
        raise SceneError(f"--after {after:g} must be a time from 0 s")
    for v in varies:
        check_values(base, v)
    return Sweep(base, plan, base.duration, check_metrics(metrics), float(after))


def check_values(base: Scene, v) -> None:
    """Every value of a grid key, and a distribution's defining numbers, make a scene that
    can run the sweep's duration (each key on the base scene): else one line."""
    if v.drawn:
        name, (a, b) = v.law
        values = {"uniform": (a, b), "integers": (a, b), "normal": (a,), "lognormal": (a,)}[name]
    else:
        values = v.values
    for value in values:
        try:
            base.replace(**overrides(base, [v], [value])).steps_for(base.duration)
        except SceneError as error:
            raise SceneError(f"--vary {v.text}: at {v.key} = {value}: {error}") from None


def sweep(scene="release", vary=(), *, samples: int | None = None, seed: int = 0,
          metrics=None, after: float = 0.0, duration: float | None = None, out=None,
          resume: bool = False, workers: int | None = None, scheduler: str | None = None,
          estimate: str | None = "off", plot=None) -> SweepResult:
    """Run a sweep: `scene` (a preset's name, a .yaml path or a Scene) with the keys of
    `vary` (a mapping {KEY: SPEC} or "KEY=SPEC" strings, as `arm-sim sweep --vary`) taken
    by every sample. Returns a SweepResult: `.columns` ({column: array or list}, so
    `pandas.DataFrame(result.columns)`), `.text` (the table's bytes), `.counts`,
    `.complete`. With `out` (a .csv path) the table, its sidecar (.json) and its picture
    (.png) are written there, as the command writes them; `resume` goes on from a table
    an interrupted sweep left. `workers`: local processes (default: every core, where the
    work is worth starting them; 1: this process); `scheduler`: a Dask cluster's address
    instead."""
    base = scene if isinstance(scene, Scene) else load_scene(scene)
    setup = make_sweep(base, vary, samples, seed, metrics, after, duration, estimate)
    if out is not None and not str(out).endswith(".csv"):
        raise SceneError(f"out {out}: the table's name must end in .csv")
    if workers is not None and workers < 1:
        raise SceneError(f"workers {workers} must be at least 1")
    from .pool import connect
    client = connect(scheduler) if scheduler else None
    result = execute(setup, out, resume, workers, client)
    if out is not None and result.complete:
        from .picture import draw
        draw(out, setup, result.columns, plot)
    return result
