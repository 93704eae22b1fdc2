"""A stable-baselines3 ``VecEnv`` over the batched environment (``taskalloc_env.vector_env``), one slot per agent.

Slot ``k * N + i`` is agent i of instance k, so one policy acts for every agent of every instance (parameter sharing,
as ``vec_env.TaskAllocVecEnv`` over env copies). The batch runs in same-step autoreset mode, SB3's convention: an
instance that ends is reset within the step, and every slot of it gets ``terminal_observation`` and
``TimeLimit.truncated`` (truncated and not terminated); its first slot gets ``episode``, the env's record (``r``,
``l``, score, valid tasks, conflicts, rounds, messages, converged; ``taskalloc_env.rewards``) plus the wall time
``t``, as ``TaskAllocVecEnv`` gives it, so SB3's ``ep_info_buffer`` counts episodes, not agents. ``seed(s)``
starts instance k from ``s + k`` at the next ``reset()``; ``action_masks()`` (and
``env_method("action_masks")``, which sb3-contrib's ``MaskablePPO`` calls) returns the masks of the last
observations::

    venv = BatchedVecEnv(taskalloc_env.vector_env(64, scenario="train_small", autoreset_mode="same_step"))
    model = MaskablePPO("MultiInputPolicy", venv, seed=0).learn(10_000)

Scripted teammates and subprocesses are ``TaskAllocVecEnv``'s; this adapter has neither.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from taskalloc_env.errors import ConfigError
from taskalloc_env.rewards import episode_record
from taskalloc_env.vector import INFO_KEYS, TaskAllocVectorEnv

MASK_METHOD = "action_masks"


class BatchedVecEnv(VecEnv):
    """``num_envs = K × N`` slots over a ``TaskAllocVectorEnv`` of K instances; see the module docstring."""

    def __init__(self, venv: TaskAllocVectorEnv) -> None:
        if venv.autoreset_mode != "same_step":
            raise ConfigError("BatchedVecEnv needs vector_env(..., autoreset_mode='same_step') (SB3 resets an "
                              f"environment within the step that ends it), got {venv.autoreset_mode!r}")
        self.venv = venv
        self.instances, self.agents_per_instance = venv.num_envs, venv.n_agents
        self._actions: np.ndarray | None = None
        self._seed: int | None = None
        self._masks = np.ones((self.instances * self.agents_per_instance, venv.single_action_space.n), dtype=bool)
        self._returns = np.zeros(self.instances)
        self._lengths = np.zeros(self.instances, dtype=np.int64)
        self._starts = np.full(self.instances, time.perf_counter())
        super().__init__(self.instances * self.agents_per_instance, venv.single_observation_space,
                         venv.single_action_space)

    def _slots(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        flat = {key: value.reshape(self.num_envs, *value.shape[2:]) for key, value in obs.items()}
        self._masks = flat["action_mask"].astype(bool)
        return flat

    # -- VecEnv API --------------------------------------------------------------------------------------------
    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Instance k gets ``seed + k`` at the next ``reset()``; one entry per slot (its instance's seed)."""
        if seed is None:
            seed = int(np.random.default_rng().integers(np.iinfo(np.uint32).max))
        self._seed = seed
        return [seed + s // self.agents_per_instance for s in range(self.num_envs)]

    def reset(self) -> dict[str, np.ndarray]:
        obs, _ = self.venv.reset(seed=self._seed)
        self._seed = None
        self._returns[:], self._lengths[:] = 0.0, 0
        self._starts[:] = time.perf_counter()
        self._reset_options()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return self._slots(obs)

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions).reshape(self.instances, self.agents_per_instance)

    def step_wait(self) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, list[dict]]:
        obs, rewards, terminations, truncations, infos = self.venv.step(self._actions)
        n = self.agents_per_instance
        self._returns += rewards[:, 0]
        self._lengths += 1
        done = terminations | truncations
        slot_infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if done.any():
            final, final_info, now = infos["final_obs"], infos["final_info"], time.perf_counter()
            for k in np.flatnonzero(done).tolist():
                cut = bool(truncations[k] and not terminations[k])
                for i in range(n):
                    slot_infos[k * n + i] = {
                        "terminal_observation": {"observation": final["observation"][k, i],
                                                 "action_mask": final["action_mask"][k, i]},
                        "TimeLimit.truncated": cut}
                figures = {key: final_info[key][k].item() for key in INFO_KEYS}
                slot_infos[k * n]["episode"] = {**episode_record(float(self._returns[k]), int(self._lengths[k]),
                                                                 figures), "t": round(now - self._starts[k], 6)}
                self._returns[k], self._lengths[k], self._starts[k] = 0.0, 0, now
        return (self._slots(obs), rewards.reshape(-1).astype(np.float32), np.repeat(done, n), slot_infos)

    def action_masks(self) -> np.ndarray:
        """(num_envs, n_actions) bool masks of the last observations."""
        return self._masks.copy()

    def has_attr(self, attr_name: str) -> bool:
        return attr_name == MASK_METHOD or hasattr(self.venv, attr_name)

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [getattr(self.venv, attr_name)] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise AttributeError(f"BatchedVecEnv cannot set {attr_name!r}: every slot shares one batched env")

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        if method_name != MASK_METHOD:
            raise AttributeError(f"BatchedVecEnv has no per-slot method {method_name!r} (only {MASK_METHOD!r})")
        masks = self.action_masks()
        return [masks[s] for s in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        return [False] * len(self._get_indices(indices))

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [None] * self.num_envs

    def close(self) -> None:
        self.venv.close()
