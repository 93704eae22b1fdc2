"""stable-baselines3 / sb3-contrib (tested with 2.9) through SuperSuit (3.11): one shared policy for every agent.

``sb3_vec_env(env, copies)`` runs SuperSuit's documented pipeline (``pettingzoo_env_to_vec_env_v1`` →
``concat_vec_envs_v1(base_class="stable_baselines3")``, one slot per agent and copy) and adds what SB3 asks of a
vector env that SuperSuit 3.11 lacks: ``seed`` (SB3 calls it when an algorithm gets ``seed=``; copy c is seeded with
seed + c) and ``has_attr`` / ``env_method("action_masks")`` (MaskablePPO reads the masks through them)::

    model = MaskablePPO("MultiInputPolicy", sb3_vec_env(taskalloc_v0.parallel_env(), copies=2), seed=0)

The project's own adapter for training, ``taskalloc.training.vec_env.TaskAllocVecEnv``, needs no SuperSuit and also sets
``TimeLimit.truncated``.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def sb3_vec_env(env: Any, copies: int = 1) -> Any:
    """A stable-baselines3 ``VecEnv`` over ``copies`` copies of the parallel ``env``, one slot per agent."""
    import supersuit
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class MaskedSeededVecEnv(VecEnvWrapper):
        def __init__(self, venv: Any) -> None:
            super().__init__(venv)
            self._masks: np.ndarray | None = None
            self._seed: int | None = None

        def seed(self, seed: int | None = None) -> list[int | None]:
            self._seed = seed                    # applied at the next reset, as SB3 expects
            return [seed] * self.num_envs

        def reset(self) -> Any:
            # SuperSuit's SB3 wrapper seeds through the seed() its inner vector env lacks: reset that one directly
            obs, self.venv.reset_infos = self.venv.venv.reset(seed=self._seed)
            self._seed = None
            self._masks = obs["action_mask"].astype(bool)
            return obs

        def step_wait(self) -> Any:
            obs, rewards, dones, infos = self.venv.step_wait()
            self._masks = obs["action_mask"].astype(bool)   # after an automatic reset: the new episode's masks
            return obs, rewards, dones, infos

        def has_attr(self, name: str) -> bool:
            return name == "action_masks" or self.venv.has_attr(name)

        def env_method(self, name: str, *args: Any, indices: Any = None, **kwargs: Any) -> list[Any]:
            if name == "action_masks":
                return list(self._masks)
            return self.venv.env_method(name, *args, indices=indices, **kwargs)

    venv = supersuit.concat_vec_envs_v1(supersuit.pettingzoo_env_to_vec_env_v1(env), copies, num_cpus=0,
                                        base_class="stable_baselines3")
    return MaskedSeededVecEnv(venv)
