"""Named scenario generators: the config field ``generator`` selects one (ours: the seam for new instance families).

``scenario`` registers ``uniform``, the test scenario of thesis §3.3.2, and ``visit``, the collaborative visit of
the decentralised task-allocation benchmarks (agents on one edge, known targets; ours after Nayak et al., IEEE RA-L
2020, and the DCTA benchmark); ``register_generator(name, fn)`` adds a family, ``fn(config, rng) -> Scenario``, and
``parallel_env(generator=name)`` uses it. A family may also register ``check(config)``, which refuses (one
``ConfigError`` line) the fields it cannot honour when the config is built, before any instance is drawn.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

Generator = Callable[[Any, Any], Any]        # (TaskAllocConfig, numpy Generator) -> Scenario
Check = Callable[[Any], None]                 # (TaskAllocConfig) -> None, raising ConfigError
GENERATORS: dict[str, Generator] = {}
CHECKS: dict[str, Check] = {}


def register_generator(name: str, generator: Generator, check: Check | None = None) -> None:
    """Make ``generator`` the one ``generator = name`` selects, with its config ``check`` (none: every config is
    accepted); re-registering a name replaces both."""
    if not (isinstance(name, str) and name.isidentifier()):
        raise ValueError(f"a generator name must be an identifier, got {name!r}")
    if not callable(generator):
        raise TypeError(f"generator {name!r} must be callable (config, rng) -> Scenario, got {generator!r}")
    if check is not None and not callable(check):
        raise TypeError(f"the check of generator {name!r} must be callable (config) -> None, got {check!r}")
    GENERATORS[name] = generator
    if check is None:
        CHECKS.pop(name, None)
    else:
        CHECKS[name] = check
