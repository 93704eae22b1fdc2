"""Fan independent work out over processes: ``parallel_map`` (results in item order) and ``as_finished`` (each
result with its index as soon as it is ready, for progress bars). Every study and check uses them.

Each worker runs torch (a learned policy's network) and the BLAS libraries on ``THREADS_PER_WORKER`` thread, so that
``jobs`` workers never ask for more than ``jobs`` cores; work done in this process (``jobs`` = 1) runs with the same
setting. The networks are small: on the 2-core machine of ``docs/benchmarks.md`` an episode of a learned policy
took 14× longer with torch's default two threads than with one (the threads wait for each other on shared cores).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any, TypeVar

Item = TypeVar("Item")

THREADS_PER_WORKER = 1
# read by torch, MKL and OpenBLAS when they start their thread pools
THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def limit_threads(threads: int) -> None:
    """A worker's initializer: the math libraries' threads at ``threads`` (the variables before they are imported,
    torch's own setting if it is already loaded)."""
    for name in THREAD_VARIABLES:
        os.environ[name] = str(threads)
    _torch_threads(threads)


def _torch_threads(threads: int) -> int | None:
    """Set torch's intra-op threads if torch is loaded; returns the previous count (None without torch)."""
    torch = sys.modules.get("torch")
    if torch is None:
        return None
    before = torch.get_num_threads()
    if before != threads:
        torch.set_num_threads(threads)
    return before


def as_finished(function: Callable[[Item], Any], items: Sequence[Item], jobs: int) -> Iterator[tuple[int, Any]]:
    """``(index, function(items[index]))`` for every item, as each finishes, over ``jobs`` processes (in this process,
    in order, when ``jobs`` ≤ 1). ``function`` must be a module-level function (it is pickled)."""
    if jobs <= 1 or len(items) < 2:
        yield from _here(function, items)
        return
    # forking a process whose torch thread pools are up can deadlock the children (a learned policy loaded in
    # this process); then workers start from a clean forkserver and load their own copy
    context = multiprocessing.get_context("forkserver" if "torch" in sys.modules else "fork")
    pool = ProcessPoolExecutor(max_workers=jobs, mp_context=context, initializer=limit_threads,
                               initargs=(THREADS_PER_WORKER,))
    try:
        # one item per task: a slow item (a search over a large instance) then holds back nothing else
        pending = {pool.submit(function, item): index for index, item in enumerate(items)}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                yield pending.pop(future), future.result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _here(function: Callable[[Item], Any], items: Sequence[Item]) -> Iterator[tuple[int, Any]]:
    """The items in this process, in order, with the workers' thread setting."""
    with worker_threads():
        for index, item in enumerate(items):
            _torch_threads(THREADS_PER_WORKER)          # the previous item may have loaded torch
            yield index, function(item)


@contextlib.contextmanager
def worker_threads() -> Iterator[None]:
    """Torch in this process on ``THREADS_PER_WORKER`` thread while the block runs (if it is loaded; its count is
    restored after)."""
    before = _torch_threads(THREADS_PER_WORKER)
    try:
        yield
    finally:
        if before is not None:
            _torch_threads(before)


def parallel_map(function: Callable[[Item], Any], items: Sequence[Item], jobs: int) -> Iterator[Any]:
    """``map(function, items)`` over ``jobs`` processes: results in item order, each as soon as it and every earlier
    one are done."""
    ready: dict[int, Any] = {}
    following = 0
    for index, result in as_finished(function, items, jobs):
        ready[index] = result
        while following in ready:
            yield ready.pop(following)
            following += 1
