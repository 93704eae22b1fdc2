"""One way to fan independent work out over processes: ``parallel_map`` (every study and check uses it)."""

from __future__ import annotations

import multiprocessing
import sys
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any, TypeVar

Item = TypeVar("Item")

MAX_CHUNK = 16          # items per task at most: a slow item then holds back little


def parallel_map(function: Callable[[Item], Any], items: Sequence[Item], jobs: int) -> Iterator[Any]:
    """``map(function, items)`` over ``jobs`` processes, results in item order (in this process when ``jobs`` ≤ 1).
    ``function`` must be a module-level function (it is pickled)."""
    if jobs <= 1 or len(items) < 2:
        yield from map(function, items)
        return
    # about eight chunks per worker keep the load balanced
    chunksize = max(1, min(MAX_CHUNK, len(items) // (8 * jobs)))
    # forking a process whose torch thread pools are up can deadlock the children (a learned policy loaded in
    # this process); then workers start from a clean forkserver and load their own copy
    context = multiprocessing.get_context("forkserver" if "torch" in sys.modules else "fork")
    with ProcessPoolExecutor(max_workers=jobs, mp_context=context) as pool:
        yield from pool.map(function, items, chunksize=chunksize)
