"""The package layout is the architecture: layers import downwards only, no cycles, no
reaching into another module's privates, and no module or class grows past its size.

    usage, interface, yaml_files, outputs   (base: import nothing of the package above it)
    physics/           model, effects/, dynamics, integrators, stability, scene, simulator, batch
    recording/         Rerun telemetry, rosbag2 writing, CSV          (imports physics)
    node/              core, parameters, commands, transports, messages (imports physics, recording)
    tools/             arm-sim and its subcommands                    (imports anything below)
"""
import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "arm_sim_ros"
LAYERS = {"usage": 0, "interface": 0, "yaml_files": 0, "outputs": 0, "physics": 1, "recording": 2, "node": 3, "tools": 4}
# Third-party modules a layer must never import (the layer's promise, in DESIGN.md).
FORBIDDEN = {
    "physics": ("rclpy", "cyclonedds", "rerun", "rosbags", "pyarrow", "sensor_msgs", "std_msgs"),
    "recording": ("rclpy", "cyclonedds"),
    "node.core": ("rclpy", "cyclonedds", "rerun"),           # the node core knows no transport
}
MAX_MODULE_LINES = 400
MAX_CLASS_LINES = 200


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def imports(name: str):
    """(imported module, imported names, line) for every import, lazy ones included."""
    path = MODULES[name]
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    return imports_in(path.read_text(), package)


def imports_in(source: str, package: list):
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, [], node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            names = [a.name for a in node.names]
            # `from . import model` imports the module arm_sim_ros.physics.model
            submodules = [f"{target}.{n}" for n in names if f"{target}.{n}" in MODULES]
            yield target, [n for n in names if f"{target}.{n}" not in MODULES], node.lineno
            for sub in submodules:
                yield sub, [], node.lineno


def layer(name: str) -> str:
    return name.split(".")[1] if name.count(".") >= 1 else ""


def own_imports(name: str, found=None):
    for target, names, line in (imports(name) if found is None else found):
        if target.startswith("arm_sim_ros.") and target != name:
            yield target, names, line


def upward_imports(name: str, found=None) -> list:
    rank = LAYERS[layer(name)]
    return [f"line {line}: {target}" for target, _, line in own_imports(name, found)
            if LAYERS.get(layer(target), 99) > rank]


def private_imports(name: str, found=None) -> list:
    return [f"{name} line {line}: {target}.{n}" for target, names, line in own_imports(name, found)
            for n in names if n.startswith("_")]


@pytest.mark.parametrize("name", [n for n in MODULES if layer(n) in LAYERS])
def test_imports_run_downwards_only(name):
    upward = upward_imports(name)
    assert not upward, f"{name} ({layer(name)}) imports a higher layer: {upward}"


@pytest.mark.parametrize("prefix, banned", FORBIDDEN.items())
def test_layers_keep_away_from_what_they_promise_not_to_use(prefix, banned):
    found = [f"{name} line {line}: {target}"
             for name in MODULES if name.startswith(f"arm_sim_ros.{prefix}")
             for target, _, line in imports(name) if target.split(".")[0] in banned]
    assert not found


def test_rerun_is_imported_only_by_recording():
    found = [name for name in MODULES for target, _, _ in imports(name)
             if target.split(".")[0] == "rerun" and layer(name) != "recording"]
    assert not found


def test_no_module_imports_another_modules_private_names():
    found = [hit for name in MODULES for hit in private_imports(name)]
    assert not found


def test_there_are_no_import_cycles():
    graph = {name: {t for t, _, _ in own_imports(name) if t in MODULES} for name in MODULES}
    # A package's __init__ importing its own modules is how packages re-export, not a cycle.
    for name in graph:
        graph[name] = {t for t in graph[name] if not (MODULES[name].name == "__init__.py"
                                                        and t.startswith(name + "."))}
    done, stack, cycles = set(), [], []

    def visit(node):
        if node in stack:
            cycles.append(stack[stack.index(node):] + [node])
            return
        if node in done:
            return
        stack.append(node)
        for nxt in sorted(graph[node]):
            visit(nxt)
        stack.pop()
        done.add(node)

    for name in sorted(graph):
        visit(name)
    assert not cycles, " ; ".join(" -> ".join(c) for c in cycles)


@pytest.mark.parametrize("name", sorted(MODULES))
def test_modules_and_classes_stay_small(name):
    source = MODULES[name].read_text()
    assert source.count("\n") <= MAX_MODULE_LINES, f"{name}: split it by responsibility"
    big = [f"{node.name}: {node.end_lineno - node.lineno + 1} lines"
           for node in ast.walk(ast.parse(source)) if isinstance(node, ast.ClassDef)
           and node.end_lineno - node.lineno + 1 > MAX_CLASS_LINES]
    assert not big


def test_the_checker_sees_a_broken_rule():
    """A physics module importing the node core lazily, and a private name, is caught."""
    source = "def f():\n    from ..node.core import ArmSimCore\nfrom .scene import _load\n"
    found = list(imports_in(source, ["arm_sim_ros", "physics"]))
    name = "arm_sim_ros.physics.probe"
    assert upward_imports(name, found) == ["line 2: arm_sim_ros.node.core"]
    assert private_imports(name, found) == [f"{name} line 3: arm_sim_ros.physics.scene._load"]
