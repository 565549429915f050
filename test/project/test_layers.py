"""The package layout is the architecture: layers import downwards only, and so do the groups
inside a layer; no cycles, no reaching into another module's privates, and no module,
class or folder grows past its size.

The allowed arrows, said once (ORDER below): a module imports from its own group, from
groups listed before its own in its layer, and from the layers before its layer. The
package's own __init__ is its front door: it re-exports what users call
(`arm_sim_ros.sweep`) lazily, from inside a function, so its imports are no arrows.
"""
import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "arm_sim_ros"
# Layers, lowest first, each with its groups (a module or a folder), lowest first.
ORDER = {
    "base": ["usage", "interface", "yaml_files", "outputs"],
    "physics": ["model", "reports", "stepping", "effects", "sensing", "dynamics", "switching", "trust",
                "angles", "scene_values", "scene", "urdf", "compiled", "simulator", "rollouts",
                "batch", "metrics"],
    "recording": ["csv_file", "readouts", "bags", "rrd"],
    "node": ["wire", "params", "commands", "services", "diagnostics", "status", "schedule",
             "stop", "recorder_link", "core", "transports", "main", "entry"],
    "tools": ["arguments", "progress", "signals", "run", "wire", "control", "accuracy", "fit",
              "sweep", "inspect", "batch", "urdf", "cli", "reference"],
    "testing": ["trace", "loop", "heard", "wire", "controller", "evidence", "plugin", "launch"],
}
LAYERS = list(ORDER)
FRONT_DOOR = "arm_sim_ros"       # the package's __init__: lazy re-exports only
# Third-party modules a layer or group must never import (its promise, in DESIGN.md).
NODE_CORE = ("rclpy", "cyclonedds", "rerun")      # the node core knows no transport
FORBIDDEN = {
    "physics": ("rclpy", "cyclonedds", "rerun", "rosbags", "pyarrow", "sensor_msgs", "std_msgs"),
    "recording": ("rclpy", "cyclonedds"),
    **{f"node.{group}": NODE_CORE for group in ("core", "commands", "params", "services")},
}
MAX_FOLDER_MODULES = 12
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


def place(name: str) -> tuple[str, str]:
    """(layer, group) of a module: arm_sim_ros.physics.trust.shadow -> ("physics", "trust")."""
    parts = name.split(".")[1:]
    if not parts:
        return "base", ""
    if parts[0] not in ORDER:
        return "base", parts[0]
    return parts[0], (parts[1] if len(parts) > 1 else "")


def rank(name: str) -> tuple[int, int]:
    """Where a module stands: its layer, then its group in that layer (a layer's own
    __init__ stands below its groups)."""
    layer, group = place(name)
    groups = ORDER[layer]
    return LAYERS.index(layer), (groups.index(group) if group in groups else -1)


def own_imports(name: str, found=None):
    for target, names, line in (imports(name) if found is None else found):
        if target.startswith("arm_sim_ros.") and target != name:
            yield target, names, line


def upward_imports(name: str, found=None) -> list:
    return [f"line {line}: {target}" for target, _, line in own_imports(name, found)
            if rank(target) > rank(name)]


def private_imports(name: str, found=None) -> list:
    return [f"{name} line {line}: {target}.{n}" for target, names, line in own_imports(name, found)
            for n in names if n.startswith("_")]


def test_every_module_stands_in_a_listed_group():
    """A new module or folder is placed in ORDER before it lands: its arrows are then known."""
    unplaced = [n for n in MODULES if place(n)[1] and place(n)[1] not in ORDER[place(n)[0]]]
    assert not unplaced


@pytest.mark.parametrize("name", sorted(set(MODULES) - {FRONT_DOOR}))
def test_imports_run_downwards_only(name):
    upward = upward_imports(name)
    assert not upward, f"{name} {place(name)} imports a higher layer or group: {upward}"


def test_the_front_door_imports_nothing_until_asked():
    """`import arm_sim_ros` (every node and tool does it first) loads nothing more: the
    re-exports are imported inside __getattr__, when first used."""
    tree = ast.parse(MODULES[FRONT_DOOR].read_text())
    assert not [node for node in tree.body if isinstance(node, (ast.Import, ast.ImportFrom))]


def test_every_folder_says_its_job_and_holds_at_most_twelve_modules():
    for folder in [PACKAGE, *sorted(p for p in PACKAGE.rglob("*") if p.is_dir()
                                   and p.name != "__pycache__")]:
        init = folder / "__init__.py"
        assert init.is_file() and ast.get_docstring(ast.parse(init.read_text())), folder
        modules = [p for p in folder.glob("*.py") if p.name != "__init__.py"]
        assert len(modules) <= MAX_FOLDER_MODULES, f"{folder}: group its {len(modules)} modules"


@pytest.mark.parametrize("prefix, banned", FORBIDDEN.items())
def test_layers_keep_away_from_what_they_promise_not_to_use(prefix, banned):
    found = [f"{name} line {line}: {target}"
             for name in MODULES if name.startswith(f"arm_sim_ros.{prefix}")
             for target, _, line in imports(name) if target.split(".")[0] in banned]
    assert not found


def test_rerun_is_imported_only_by_recording():
    found = [name for name in MODULES for target, _, _ in imports(name)
             if target.split(".")[0] == "rerun" and place(name)[0] != "recording"]
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
    """A trust module importing the node core lazily (a higher layer), the scene (a higher
    group of its own layer), and a private name, is caught."""
    source = "def f():\n    from ...node.core import ArmSimCore\nfrom ..scene import _load\n"
    found = list(imports_in(source, ["arm_sim_ros", "physics", "trust"]))
    name = "arm_sim_ros.physics.trust.probe"
    assert sorted(upward_imports(name, found)) == ["line 2: arm_sim_ros.node.core",
                                                   "line 3: arm_sim_ros.physics.scene"]
    assert private_imports(name, found) == [f"{name} line 3: arm_sim_ros.physics.scene._load"]
