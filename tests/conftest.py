"""Test configuration: Hypothesis profiles.

``HYPOTHESIS_PROFILE=ci`` (what ``scripts/test.sh`` and CI use) derandomises the property tests: every run draws
the same examples, so a failure in CI fails again on any machine, and ``print_blob`` prints the line that replays
it. The default ``dev`` profile explores new examples each run and keeps the failing ones in ``.hypothesis/`` so
they are tried first next time. Example counts are set per test (``settings(max_examples=examples(…))``): the
whole suite draws the full count, the fast subset (``-m "not slow"``) a twentieth of it (``helpers.examples``).
"""

from __future__ import annotations

import os

import helpers
from hypothesis import settings
from hypothesis.database import DirectoryBasedExampleDatabase

settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
settings.register_profile("dev", database=DirectoryBasedExampleDatabase(".hypothesis/examples"), print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "dev"))


def pytest_configure(config) -> None:
    """A run that deselects the slow tests is the fast subset: its property tests draw fewer examples."""
    helpers.FAST_SUBSET = "not slow" in (config.option.markexpr or "")
