"""The packages form layers that only import downwards, and no package's modules import each other in a cycle.

taskalloc_env (the environment) < policies (every policy and the centralised solvers) < evaluation (paired runs,
statistics, reports, experiments) < training (reinforcement learning) < benchmarks (speed scripts). Imports inside
functions count too. ``__main__`` modules are command entry points that nothing imports; they are left out.
"""

from __future__ import annotations

import ast
import graphlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
LAYERS = ("taskalloc_env", "policies", "evaluation", "training", "benchmarks")


def project_imports(path: Path) -> set[str]:
    """Dotted names of the project modules ``path`` imports (anywhere in the file)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return {n for n in names if n.split(".")[0] in LAYERS}


def modules() -> dict[str, Path]:
    found = {}
    for package in LAYERS:
        for path in sorted((ROOT / package).rglob("*.py")):
            if path.name == "__main__.py":
                continue
            dotted = ".".join(path.relative_to(ROOT).with_suffix("").parts)
            found[dotted.removesuffix(".__init__")] = path
    return found


@pytest.mark.parametrize("package", LAYERS)
def test_packages_import_only_lower_layers(package):
    rank = LAYERS.index(package)
    upward = []
    for name, path in modules().items():
        if name.split(".")[0] != package:
            continue
        for imported in project_imports(path):
            if LAYERS.index(imported.split(".")[0]) > rank:
                upward.append(f"{path.relative_to(ROOT)} imports {imported}")
    assert not upward, "imports from a higher layer:\n" + "\n".join(upward)


def test_no_import_cycles_between_modules():
    mods = modules()
    graph = {name: {m for m in project_imports(path) if m in mods and m not in LAYERS and m != name}
             for name, path in mods.items() if name not in LAYERS}
    try:
        graphlib.TopologicalSorter(graph).prepare()
    except graphlib.CycleError as exc:
        pytest.fail(f"import cycle: {' -> '.join(exc.args[1])}")


def test_the_check_sees_an_upward_import(tmp_path):
    """The checker itself catches a lower layer importing a higher one (so the tests above can fail)."""
    bad = tmp_path / "bad.py"
    bad.write_text("def f():\n    from training.train import main\n")
    assert "training.train" in project_imports(bad)
