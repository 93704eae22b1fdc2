"""``taskalloc/TaskAlloc-v0``: re-exports ``env``, ``parallel_env`` and ``raw_env`` (card: ``taskalloc_env.env``)."""

from __future__ import annotations

from typing import Any

from pettingzoo.utils import wrappers
from pettingzoo.utils.conversions import parallel_to_aec

from taskalloc_env.env import TaskAllocEnv

__all__ = ["env", "parallel_env", "raw_env"]


def parallel_env(**kwargs: Any) -> TaskAllocEnv:
    """The parallel environment; keyword arguments as ``TaskAllocEnv``."""
    return TaskAllocEnv(**kwargs)


def raw_env(**kwargs: Any):
    """The AEC view of the parallel environment."""
    return parallel_to_aec(parallel_env(**kwargs))


def env(**kwargs: Any):
    """The AEC view with PettingZoo's order-enforcing wrapper."""
    return wrappers.OrderEnforcingWrapper(raw_env(**kwargs))
