"""TorchRL (tested with torchrl 0.14): the batched environment as an ``EnvBase`` of batch size ``[K]``.

``TaskAllocTorchRLEnv(num_envs, **env_kwargs)`` wraps ``taskalloc_env.vector_env`` (``autoreset_mode="disabled"``:
TorchRL resets the instances that ended through ``"_reset"``) with the keys of TorchRL's own ``PettingZooWrapper``,
so multi-agent code written for that wrapper runs unchanged: the agents form one group, ``uav``, with
``("uav", "observation")`` (K, N, D), ``("uav", "action_mask")`` (K, N, A) bool, ``("uav", "action")`` (K, N)
categorical, ``("uav", "reward")`` (K, N, 1) and ``("uav", "done" | "terminated" | "truncated")`` (K, N, 1); the
root holds ``done``, ``terminated`` and ``truncated`` (K, 1), the global ``state`` (K, S) for a centralised critic,
and the episode's figures (``score``, ``valid_tasks``, ``conflicts``, ``round``, ``messages``, ``invalid_actions``)::

    env = TaskAllocTorchRLEnv(256, scenario="train_small")
    rollout = env.rollout(100, policy, break_when_any_done=False)     # (256, 100) tensordict

Instance k starts from ``seed + k`` after ``set_seed(seed)``; later episodes continue its generator.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Binary, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from taskalloc_env.vector import TaskAllocVectorEnv, vector_env

GROUP = "uav"
FIGURES = ("score", "valid_tasks", "conflicts", "round", "messages", "invalid_actions")


class TaskAllocTorchRLEnv(EnvBase):
    """K instances as one TorchRL environment of batch size ``[K]``; see the module docstring."""

    def __init__(self, num_envs: int, device: str | torch.device = "cpu", **env_kwargs: Any) -> None:
        self.venv: TaskAllocVectorEnv = vector_env(num_envs, autoreset_mode="disabled", **env_kwargs)
        super().__init__(batch_size=torch.Size([num_envs]), device=device)
        self._seed: int | None = None
        self._make_specs()

    def _make_specs(self) -> None:
        v = self.venv
        k, n, a = v.num_envs, v.n_agents, int(v.single_action_space.n)
        d = v.single_observation_space["observation"].shape[0]
        dtype = torch.float32 if v.single_observation_space["observation"].dtype == np.float32 else torch.float64
        group = (k, n)
        self.observation_spec = Composite({
            GROUP: Composite({"observation": Unbounded((*group, d), dtype=dtype),
                              "action_mask": Binary(n=a, shape=(*group, a), dtype=torch.bool)}, shape=group),
            "state": Unbounded((k, v.state_space.shape[1]), dtype=dtype),
            **{key: Unbounded((k, 1), dtype=torch.float64 if key == "score" else torch.int64) for key in FIGURES},
        }, shape=(k,))
        self.action_spec = Composite({GROUP: Composite({"action": Categorical(a, shape=group)}, shape=group)},
                                     shape=(k,))
        self.reward_spec = Composite({GROUP: Composite({"reward": Unbounded((*group, 1))}, shape=group)}, shape=(k,))
        flags = ("done", "terminated", "truncated")
        self.done_spec = Composite({
            **{flag: Categorical(2, (k, 1), dtype=torch.bool) for flag in flags},
            GROUP: Composite({flag: Categorical(2, (*group, 1), dtype=torch.bool) for flag in flags}, shape=group),
        }, shape=(k,))

    def _set_seed(self, seed: int | None) -> None:
        self._seed = seed

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        mask = None
        if tensordict is not None and "_reset" in tensordict:
            mask = tensordict.get("_reset").reshape(-1).cpu().numpy().astype(bool)
        first = not self.venv._started
        options = None if first or mask is None else {"reset_mask": mask}
        obs, infos = self.venv.reset(seed=self._seed if first or self._seed is not None else None, options=options)
        self._seed = None
        done = torch.zeros((self.venv.num_envs, 1), dtype=torch.bool)
        return self._tensordict(obs, infos, done, done, done)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        actions = tensordict.get((GROUP, "action")).cpu().numpy()
        obs, rewards, terminated, truncated, infos = self.venv.step(actions.astype(np.int64))
        term = torch.as_tensor(terminated).unsqueeze(-1)
        trunc = torch.as_tensor(truncated).unsqueeze(-1)
        out = self._tensordict(obs, infos, term | trunc, term, trunc)
        out.set((GROUP, "reward"), torch.as_tensor(rewards, dtype=torch.float32).unsqueeze(-1))
        return out

    def _tensordict(self, obs: dict[str, np.ndarray], infos: dict[str, np.ndarray], done: torch.Tensor,
                    terminated: torch.Tensor, truncated: torch.Tensor) -> TensorDictBase:
        k, n = self.venv.num_envs, self.venv.n_agents
        dtype = self.observation_spec[GROUP, "observation"].dtype
        flags = {"done": done, "terminated": terminated, "truncated": truncated}
        group = TensorDict({
            "observation": torch.as_tensor(obs["observation"], dtype=dtype),
            "action_mask": torch.as_tensor(obs["action_mask"] > 0),
            **{flag: value.unsqueeze(1).expand(k, n, 1).clone() for flag, value in flags.items()},
        }, batch_size=(k, n))
        return TensorDict({
            GROUP: group, **flags,
            "state": torch.as_tensor(self.venv.state(), dtype=dtype),
            **{key: torch.as_tensor(infos[key]).reshape(k, 1).to(torch.float64 if key == "score" else torch.int64)
               for key in FIGURES},
        }, batch_size=(k,), device=self.device)
