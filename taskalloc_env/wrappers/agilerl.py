"""AgileRL (tested with 2.58): the plain observation Box, the action mask in ``infos[agent]["action_mask"]``.

AgileRL's multi-agent algorithms read masks from infos and assert that no observation holds one::

    env = MaskInInfos(taskalloc_v0.parallel_env(scenario="train_small"))
"""

from __future__ import annotations

from typing import Any

import numpy as np

from taskalloc_env.wrappers._obs import ObservationWrapper


class MaskInInfos(ObservationWrapper):
    """``{"observation", "action_mask"}`` → the observation array; the mask goes to the agent's info."""

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        self.space = env.observation_space(env.possible_agents[0])["observation"]

    def observation(self, obs: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        info["action_mask"] = obs["action_mask"]
        return obs["observation"]
