"""taskalloc: the installed namespace of the project's policies, evaluation and training layers.

``taskalloc.policies``, ``taskalloc.evaluation`` and ``taskalloc.training`` are the repository's top-level folders
``policies/``, ``evaluation/`` and ``training/``. The wheel places them inside this package (``pyproject.toml``,
``force-include``); in a checkout this package's search path also holds the checkout's root, so the same dotted names
resolve to the same files without a build step (``docs/decisions.md``, "One installed namespace"). The environment
itself is ``taskalloc_env`` (PettingZoo's ``<name>_env`` convention).
"""

from __future__ import annotations

from pathlib import Path

_CHECKOUT = Path(__file__).resolve().parent.parent
if (_CHECKOUT / "pyproject.toml").is_file() and (_CHECKOUT / "policies" / "__init__.py").is_file():
    __path__.append(str(_CHECKOUT))  # a checkout: taskalloc.policies is <checkout>/policies

__version__ = "0.3.0"
