"""A parallel wrapper that reshapes each observation (the shared part of the RLlib and AgileRL adapters)."""

from __future__ import annotations

import abc
from typing import Any

from gymnasium import spaces
from pettingzoo.utils.wrappers import BaseParallelWrapper


class ObservationWrapper(BaseParallelWrapper, abc.ABC):
    """Applies ``observation`` to every agent's observation; ``space`` is the new observation space of all agents."""

    space: spaces.Space

    def observation_space(self, agent: str) -> spaces.Space:
        self.env.observation_space(agent)       # keeps the env's unknown-agent check
        return self.space

    @abc.abstractmethod
    def observation(self, obs: dict[str, Any], info: dict[str, Any]) -> Any:
        """The observation the library reads, from the env's ``{"observation", "action_mask"}`` and the info."""

    def reset(self, seed: int | None = None, options: dict | None = None):
        obs, infos = self.env.reset(seed=seed, options=options)
        return {a: self.observation(o, infos[a]) for a, o in obs.items()}, infos

    def step(self, actions: dict[str, Any]):
        obs, rewards, terminations, truncations, infos = self.env.step(actions)
        return {a: self.observation(o, infos[a]) for a, o in obs.items()}, rewards, terminations, truncations, infos
