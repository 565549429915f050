"""The pytest plugin, installed with the package (entry point pytest11): fixtures that run
your controller against the arm, and the evidence a failing test leaves.

- `arm`: in process. `arm.run(controller, scene, seconds, ...)` runs a Python callable
  against a scene (loop.closed_loop) and returns its Trace.
- `arm_node`: over the wire. `arm_node(scene, parameters)` starts the node in a subprocess
  on a private ROS_DOMAIN_ID, on loopback, in lockstep (wire.WireArm); your controller joins
  that domain (`node.domain_id`, `node.env`); `node.run(seconds)` returns the Trace.
  Stopped at the end of the test.

When a test that used either fails, its traces are written to its tmp dir as CSV, a Rerun
recording and a PNG of q, the reference and the torques, and the report names them.
"""
from __future__ import annotations

import pytest

EVIDENCE = pytest.StashKey[dict]()


def kept(traces: dict, source, run, *args, **options):
    """run(*args, **options)'s trace, kept in `traces` under `source` for the evidence (a
    node's latest replaces its earlier: each holds the whole run so far), a ControllerError's
    too."""
    from .loop import ControllerError
    try:
        traces[source] = run(*args, **options)
    except ControllerError as error:
        if error.trace is not None:
            traces[source] = error.trace
        raise
    return traces[source]


class Arm:
    """The `arm` fixture: closed loops in process, each trace kept for the evidence."""

    def __init__(self, traces: dict):
        self.traces = traces

    def run(self, controller, scene="release", seconds: float = 1.0, **options):
        """loop.closed_loop(controller, scene, seconds, **options): its Trace (rate=,
        command=, reference=, overrides=)."""
        from .loop import closed_loop
        return kept(self.traces, len(self.traces), closed_loop, controller, scene, seconds,
                    **options)


class ArmNodes:
    """The `arm_node` fixture: nodes in lockstep over the wire, stopped after the test."""

    def __init__(self, directory, traces: dict, monkeypatch):
        self.directory, self.traces, self.nodes = directory, traces, []
        self.monkeypatch = monkeypatch

    def __call__(self, scene: str = "release", parameters: dict | None = None, **options):
        from .wire import WireArm
        node = WireArm(scene, parameters, directory=self.directory, **options)
        self.nodes.append(node)
        for name in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):   # rclpy.init() joins
            self.monkeypatch.setenv(name, node.env[name])
        run = node.run
        node.run = lambda seconds: kept(self.traces, node, run, seconds)
        return node

    def close(self) -> None:
        for node in self.nodes:
            node.close()


@pytest.fixture
def arm(request):
    """Run a controller (a Python callable: Reading -> two numbers) against a scene, in
    process: `arm.run(controller, "release", seconds=2.0, rate=1000.0, reference=[...])`."""
    return Arm(request.node.stash.setdefault(EVIDENCE, {}))


@pytest.fixture
def arm_node(request, tmp_path, monkeypatch):
    """Start the node in lockstep on a private domain: `node = arm_node("release")`, then
    your controller on `node.domain_id` (for the test, this process's ROS_DOMAIN_ID and
    ROS_AUTOMATIC_DISCOVERY_RANGE are the node's: rclpy.init() joins it), then
    `node.run(seconds)`."""
    nodes = ArmNodes(tmp_path, request.node.stash.setdefault(EVIDENCE, {}), monkeypatch)
    yield nodes
    nodes.close()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    traces = list(item.stash.get(EVIDENCE, {}).values())
    if report.when != "call" or not report.failed or not traces:
        return
    from .evidence import write
    directory = _tmp_dir(item)
    lines = []
    for k, trace in enumerate(traces):
        stem = f"trace{k + 1}" if len(traces) > 1 else "trace"
        try:
            paths = write(trace, directory, stem)
        except Exception as error:    # noqa: BLE001 - evidence must not hide the failure
            lines.append(f"{stem}: could not be written ({type(error).__name__}: {error})")
            continue
        lines.append(f"{stem} ({trace.scene}, {len(trace)} rows to t = {trace.t[-1]:g} s):")
        lines += [f"  {kind}: {path}" for kind, path in paths.items()]
    report.sections.append(("arm_sim evidence", "\n".join(lines)))


def _tmp_dir(item):
    """The test's own tmp dir (tmp_path's), made if the test did not ask for it."""
    if "tmp_path" in item.funcargs:
        return item.funcargs["tmp_path"]
    factory = item.config._tmp_path_factory      # what the tmp_path fixture makes it with
    name = "".join(c if c.isalnum() or c in "-_" else "_" for c in item.name)[:30]
    return factory.mktemp(f"{name}_evidence", numbered=True)
