"""Named scenario generators: the config field ``generator`` selects one (ours: the seam for new instance families).

``scenario`` registers ``uniform``, the test scenario of thesis §3.3.2; ``register_generator(name, fn)`` adds a
family, ``fn(config, rng) -> Scenario``, and ``parallel_env(generator=name)`` uses it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

Generator = Callable[[Any, Any], Any]        # (TaskAllocConfig, numpy Generator) -> Scenario
GENERATORS: dict[str, Generator] = {}


def register_generator(name: str, generator: Generator) -> None:
    """Make ``generator`` the one ``generator = name`` selects; re-registering a name replaces it."""
    if not (isinstance(name, str) and name.isidentifier()):
        raise ValueError(f"a generator name must be an identifier, got {name!r}")
    if not callable(generator):
        raise TypeError(f"generator {name!r} must be callable (config, rng) -> Scenario, got {generator!r}")
    GENERATORS[name] = generator
