"""One interface for every policy, scripted or learned.

A policy is bound to an environment once per episode (``start``), then maps the observations (and infos) of the
live agents to their actions (``act``). ``env_overrides`` names the protocol options the policy needs from the
environment (e.g. ``task_quitting`` for CBGA with task quitting); runners build the environment with them.
"""

from __future__ import annotations

import abc
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from taskalloc_env.env import TaskAllocEnv
from taskalloc_env.observation import ObservationLayout


class Policy(abc.ABC):
    """Base class: subclasses implement ``act`` and may override ``start`` and ``env_overrides``."""

    name: str = "policy"

    def __init__(self) -> None:
        self._env: TaskAllocEnv | None = None

    @property
    def env_overrides(self) -> dict[str, Any]:
        """Config fields the environment must have for this policy (empty: any environment)."""
        return {}

    def start(self, env: Any, seed: int | None = None) -> None:
        """Bind to ``env`` (any PettingZoo wrapper of a ``TaskAllocEnv``) at the start of an episode."""
        unwrapped = env.unwrapped
        if not isinstance(unwrapped, TaskAllocEnv):
            raise TypeError(f"{self.name} needs a TaskAllocEnv, got {type(unwrapped).__name__}")
        self._env = unwrapped
        wrong = {k: (getattr(unwrapped.config, k), v) for k, v in self.env_overrides.items()
                 if getattr(unwrapped.config, k) != v}
        if wrong:
            detail = ", ".join(f"{k}={have!r} (needs {want!r})" for k, (have, want) in wrong.items())
            raise ValueError(f"{self.name} needs an environment with {self.env_overrides}; this one has {detail}. "
                             "Build it with parallel_env(..., **policy.env_overrides).")

    @property
    def env(self) -> TaskAllocEnv:
        if self._env is None:
            raise RuntimeError(f"{self.name}: call start(env) before act()")
        return self._env

    @property
    def layout(self) -> ObservationLayout:
        return self.env.observation_layout

    @property
    def n_tasks(self) -> int:
        return self.env.config.n_tasks

    @abc.abstractmethod
    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        """The action of every agent in ``observations`` (agent name → action index)."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"


def stack_observations(observations: Mapping[str, Mapping[str, np.ndarray]], agents: Sequence[str]
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The ``agents``' observations (A, D) and action masks (A, 1 + 2M), stacked in that order (``np.array`` on the
    rows: the same array as ``np.stack``, a few times faster on a step's handful of rows)."""
    return (np.array([observations[a]["observation"] for a in agents]),
            np.array([observations[a]["action_mask"] for a in agents]))
