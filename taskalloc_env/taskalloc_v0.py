"""``taskalloc/TaskAlloc-v0``: re-exports ``env``, ``parallel_env`` and ``raw_env`` (card: ``taskalloc_env.env``)."""

from __future__ import annotations

from typing import Any

from pettingzoo.utils import wrappers
from pettingzoo.utils.conversions import parallel_to_aec_wrapper

from taskalloc_env.env import TaskAllocEnv

__all__ = ["env", "parallel_env", "raw_env"]


def parallel_env(**kwargs: Any) -> TaskAllocEnv:
    """The parallel environment; keyword arguments as ``TaskAllocEnv``."""
    return TaskAllocEnv(**kwargs)


class _AECView(parallel_to_aec_wrapper):
    """PettingZoo's AEC view of the parallel env, which with ``invalid_action="raise"`` checks each action when it is
    given: the parallel env sees a turn's actions only after the last agent has chosen, too late to name the culprit.
    """

    def step(self, action: Any) -> None:
        agent = self.agent_selection
        env = self.env.unwrapped
        if env.invalid_action == "raise" and not (self.terminations.get(agent) or self.truncations.get(agent)):
            env.validate_action(agent, action)
        super().step(action)


def raw_env(**kwargs: Any):
    """The AEC view of the parallel environment."""
    return _AECView(parallel_env(**kwargs))


def env(**kwargs: Any):
    """The AEC view with PettingZoo's order-enforcing wrapper."""
    return wrappers.OrderEnforcingWrapper(raw_env(**kwargs))
