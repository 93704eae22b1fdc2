"""Compiled kernels (numba) of the hot loops; the numpy code they mirror stays the reference.

* ``merge.exchange_all``: a round's deliveries on the receivers' tables (``consensus.exchange_reference``);
* ``plan.plan_paths``: path timing and insertion gains (``scoring.ScoringModel.plan_reference``);

Without numba (``COMPILED`` false) the numpy references run instead. ``tests/test_kernels.py`` compares each
kernel with its reference on random inputs.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

try:
    import numba
except ImportError:          # pragma: no cover - numba is a dependency; the references still work without it
    numba = None

COMPILED = numba is not None


def jit(function: Callable[..., Any]) -> Callable[..., Any]:
    """``numba.njit`` with an on-disk cache, or the function itself without numba."""
    return numba.njit(cache=True, nogil=True)(function) if COMPILED else function
