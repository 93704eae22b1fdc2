"""Test configuration: hypothesis profiles.

``HYPOTHESIS_PROFILE=ci`` makes the property tests derandomised (the same examples on every run); the default
profile explores new examples each run. Example counts are set per test (``settings(max_examples=…)``).
"""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, print_blob=True)
settings.register_profile("dev", print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "dev"))
