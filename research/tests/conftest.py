"""Research tests run in the full suite, never in the fast subset: every one is marked slow. ``research`` is
imported (its policies, loaders and models registered) and the product's test helpers (``tests/helpers.py``) are
importable as ``helpers``."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

import research  # noqa: F401  (registers research's plug-ins)

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent.parent / "tests"))


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if Path(str(item.fspath)).resolve().is_relative_to(HERE):
            item.add_marker(pytest.mark.slow)
