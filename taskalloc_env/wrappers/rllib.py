"""Ray RLlib (tested with 2.60, new API stack): observation keys for its action-masking RLModule.

``ray.rllib.examples.rl_modules.classes.action_masking_rlm.ActionMaskingTorchRLModule`` reads the keys
``observations`` and ``action_mask``; this env names the first ``observation`` (PettingZoo's convention)::

    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
    register_env("taskalloc", lambda cfg: ParallelPettingZooEnv(RLlibObservations(taskalloc_v0.parallel_env(**cfg))))
"""

from __future__ import annotations

from typing import Any

from gymnasium import spaces

from taskalloc_env.wrappers._obs import ObservationWrapper


class RLlibObservations(ObservationWrapper):
    """``{"observation", "action_mask"}`` → ``{"observations", "action_mask"}``."""

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        inner = env.observation_space(env.possible_agents[0])
        self.space = spaces.Dict({"observations": inner["observation"], "action_mask": inner["action_mask"]})

    def observation(self, obs: dict[str, Any], info: dict[str, Any]) -> dict[str, Any]:
        return {"observations": obs["observation"], "action_mask": obs["action_mask"]}
