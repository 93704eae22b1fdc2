"""A missing optional dependency names the extra that brings it (not a bare traceback from deep inside an import)."""

from __future__ import annotations

import subprocess
import sys

import pytest

BLOCK = "import sys; sys.modules[{name!r}] = None; "     # a None entry makes `import name` fail like a missing package


@pytest.mark.parametrize(("blocked", "module", "extra"), [
    ("torch", "training", "taskalloc[train]"),
    ("sb3_contrib", "taskalloc.training.train", "taskalloc[train]"),
])
def test_a_missing_extra_is_named(blocked, module, extra):
    code = BLOCK.format(name=blocked) + f"import {module}"
    if blocked == "torch":          # find_spec ignores sys.modules: hide torch from the import system instead
        code = ("import importlib.util, sys; real = importlib.util.find_spec; "
                "importlib.util.find_spec = lambda n, *a: None if n == 'torch' else real(n, *a); "
                f"sys.modules['torch'] = None; import {module}")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode != 0
    assert extra in result.stderr.strip().splitlines()[-1]
