"""The packages form layers that only import downwards, and no package's modules import each other in a cycle.

taskalloc_env (the environment) < taskalloc.policies (every policy and the centralised solvers) < taskalloc.evaluation
(paired runs, statistics, reports, experiments) < taskalloc.training (reinforcement learning) < taskalloc.cli (the
console command) < benchmarks (speed scripts) < research (studies outside the wheel). Imports inside functions count
too. ``__main__`` modules are command entry points that nothing imports; they are left out. The product (everything
below ``benchmarks``) never imports ``research``, and the built wheel holds only the two namespaces.
"""

from __future__ import annotations

import ast
import graphlib
import json
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
LAYERS = ("taskalloc_env", "taskalloc.policies", "taskalloc.evaluation", "taskalloc.training", "taskalloc.cli",
          "benchmarks", "research")
# the folder of each layer in a checkout (the wheel maps policies/ to taskalloc/policies/, see pyproject.toml)
FOLDERS = {"taskalloc_env": "taskalloc_env", "taskalloc.policies": "policies", "taskalloc.evaluation": "evaluation",
           "taskalloc.training": "training", "taskalloc.cli": "taskalloc", "benchmarks": "benchmarks",
           "research": "research"}
PRODUCT = LAYERS[: LAYERS.index("benchmarks")]
# docs/decisions.md, "Product and research": the three models of the product's trainers, and the leaderboard's
# learned runs (docs/benchmark.md: every ``learned:<name>`` run of results/benchmark/v0/*/summary.json)
LEADERBOARD_MODELS = sorted({run.split(":", 1)[1]
                             for path in (ROOT / "results" / "benchmark" / "v0").glob("*/summary.json")
                             for run in json.loads(path.read_text(encoding="utf-8"))["runs"]
                             if run.startswith("learned:")})
PRODUCT_MODELS = sorted({"mappo_small", "mappo_small_pooling_1m", "train_small", *LEADERBOARD_MODELS})


def layer(name: str) -> str | None:
    """The layer a dotted module name belongs to (``taskalloc`` itself and ``taskalloc.cli`` are the command layer)."""
    for candidate in sorted(LAYERS, key=len, reverse=True):
        if name == candidate or name.startswith(candidate + "."):
            return candidate
    return "taskalloc.cli" if name == "taskalloc" else None


def project_imports(path: Path) -> set[str]:
    """Dotted names of the project modules ``path`` imports (anywhere in the file)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return {n for n in names if layer(n) is not None}


def modules() -> dict[str, Path]:
    found = {}
    for package, folder in FOLDERS.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            if path.name == "__main__.py":
                continue
            parts = path.relative_to(ROOT / folder).with_suffix("").parts
            dotted = ".".join((package, *parts)) if package != "taskalloc.cli" else ".".join(("taskalloc", *parts))
            found[dotted.removesuffix(".__init__")] = path
    return found


@pytest.mark.parametrize("package", LAYERS)
def test_packages_import_only_lower_layers(package):
    rank = LAYERS.index(package)
    upward = []
    for name, path in modules().items():
        if layer(name) != package:
            continue
        for imported in project_imports(path):
            if LAYERS.index(layer(imported)) > rank:
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
    bad.write_text("def f():\n    from taskalloc.training.train import main\n")
    assert "taskalloc.training.train" in project_imports(bad)
    assert layer("taskalloc.training.train") == "taskalloc.training" and layer("research.planner") == "research"


def test_no_module_imports_the_bare_folder_names():
    """Code imports ``taskalloc.policies``, never the checkout's folder ``policies`` (which the wheel does not have)."""
    bare = []
    for path in [p for folder in FOLDERS.values() for p in (ROOT / folder).rglob("*.py")] + list(
            (ROOT / "tests").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module] if isinstance(node, ast.ImportFrom) and node.module and node.level == 0 else [])
            bare += [f"{path.relative_to(ROOT)}: {n}" for n in names
                     if n.split(".")[0] in {"policies", "evaluation", "training"}]
    assert not bare, "imports of bare folder names:\n" + "\n".join(bare)


def research_imports(path: Path) -> list[str]:
    """Where ``path`` names ``research`` in an import: ``import``/``from`` statements, ``importlib.import_module``
    and ``__import__`` with a literal module name."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                 [node.module] if isinstance(node, ast.ImportFrom) and node.module else [])
        if isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant):
            func = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
            if func in {"import_module", "__import__"} and isinstance(node.args[0].value, str):
                names.append(node.args[0].value)
        found += [f"line {node.lineno}: {n}" for n in names if n.split(".")[0] == "research"]
    return found


def test_no_product_module_imports_research(tmp_path):
    """The product (taskalloc_env, policies, evaluation, training, taskalloc/) never names ``research`` in an import;
    research plugs in through the registries and the partner hook (docs/decisions.md, "Product and research")."""
    product = [p for package in PRODUCT for p in sorted((ROOT / FOLDERS[package]).rglob("*.py"))]
    assert len(product) > 50
    found = [f"{p.relative_to(ROOT)} {hit}" for p in product for hit in research_imports(p)]
    assert not found, "the product imports research:\n" + "\n".join(found)
    bad = tmp_path / "bad.py"      # the check sees each form
    bad.write_text("import research\nfrom research.plugins import register\n"
                   "def f():\n    import importlib\n    importlib.import_module('research.training.planner')\n")
    assert len(research_imports(bad)) == 3


@pytest.mark.slow
def test_importing_the_whole_product_loads_no_research_module():
    names = [n for n in modules() if layer(n) in PRODUCT]
    code = ("import importlib, sys\n"
            f"for name in {names!r}:\n"
            "    try:\n        importlib.import_module(name)\n"
            "    except ImportError as exc:\n        assert 'research' not in str(exc), exc\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'research'))\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_the_product_keeps_only_its_listed_committed_models():
    """models/ holds the product's learned models (docs/decisions.md, "Product and research"); research's are in
    research/models."""
    committed = sorted(p.name for p in (ROOT / "models").iterdir() if (p / "model.json").is_file())
    assert committed == PRODUCT_MODELS


@pytest.mark.slow
def test_the_wheel_holds_one_namespace_and_no_research(tmp_path):
    """Build the wheel and read its entries: top-level names are ``taskalloc`` and ``taskalloc_env`` only."""
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(ROOT)],
                   check=True, capture_output=True, timeout=600)
    entries = zipfile.ZipFile(next(tmp_path.glob("taskalloc-*.whl"))).namelist()
    tops = {e.split("/")[0] for e in entries if not e.split("/")[0].endswith(".dist-info")}
    assert tops == {"taskalloc", "taskalloc_env"}, tops
    assert "taskalloc/policies/__init__.py" in entries and "taskalloc/training/mappo.py" in entries
    assert not [e for e in entries if "research" in e.split("/") or e.startswith(("tests/", "benchmarks/"))]
    models = {e.split("/")[3] for e in entries if e.startswith("taskalloc_env/_data/models/") and e.count("/") > 3}
    assert models == set(PRODUCT_MODELS), models
