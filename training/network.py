"""Torch policy networks for the taskalloc observation, as SB3 / sb3-contrib actor-critic policies.

The observation is ``[own features | task_0 features | … | task_{M−1} features]`` plus the action mask
(``taskalloc_env.observation``). Two bodies:

* ``pooling`` (default): every task's features, concatenated with the agent's own features, go through one shared
  encoder; mean- and max-pooling over tasks gives a context. Each task's embedding concatenated with the context
  gives that task's *bid* and *quit* logits, the context alone the *pass* logit (a Deep-Sets network,
  Zaheer et al. 2017). No weight depends on M, so one set of weights serves any number of tasks.
* ``mlp``: a plain MLP from the flat observation to the 1 + 2M logits (fixed M).

Either way the action mask is applied to the logits inside the network (invalid actions get −1e8), so plain PPO
never samples an invalid action; MaskablePPO masks again, which changes nothing. Actor and critic have separate
encoders. The features extractor only concatenates ``observation`` and ``action_mask``; the body (SB3's
``mlp_extractor``) does the rest and outputs the masked logits, so the policy's ``action_net`` is the identity.
"""

from __future__ import annotations

import itertools
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from sb3_contrib.common.maskable.policies import MaskableActorCriticPolicy
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from taskalloc_env.observation import TASK_FEATURES

BODIES = ("pooling", "mlp")
MASKED_LOGIT = -1e8


class MaskedObsExtractor(BaseFeaturesExtractor):
    """``Dict(observation, action_mask)`` → ``[observation | action_mask]`` (no parameters)."""

    def __init__(self, observation_space: gym.spaces.Dict) -> None:
        width = observation_space["observation"].shape[0] + observation_space["action_mask"].shape[0]
        super().__init__(observation_space, features_dim=width)

    def forward(self, observations: dict[str, th.Tensor]) -> th.Tensor:
        return th.cat([observations["observation"].float(), observations["action_mask"].float()], dim=-1)


def split_features(features: th.Tensor, own_size: int, task_size: int) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
    """``[own | tasks | mask]`` → own (B, O), tasks (B, M, F), mask (B, 1 + 2M) bool; M follows from the width."""
    n_tasks, rest = divmod(features.shape[-1] - own_size - 1, task_size + 2)
    if rest or n_tasks < 1:
        raise ValueError(f"feature width {features.shape[-1]} does not fit own_size={own_size}, "
                         f"task_size={task_size}: expected own + M * (task_size + 2) + 1")
    own = features[:, :own_size]
    tasks = features[:, own_size: own_size + n_tasks * task_size].reshape(-1, n_tasks, task_size)
    mask = features[:, own_size + n_tasks * task_size:] > 0.5
    return own, tasks, mask


def mlp(sizes: list[int], activate_last: bool = True) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(itertools.pairwise(sizes)):
        layers.append(nn.Linear(a, b))
        if activate_last or i < len(sizes) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


class PoolingEncoder(nn.Module):
    """Per-task embeddings from a shared encoder and a context from mean- and max-pooling them."""

    def __init__(self, own_size: int, task_size: int, hidden: int) -> None:
        super().__init__()
        self.encode = mlp([task_size + own_size, hidden, hidden])
        self.context = mlp([2 * hidden, hidden])

    def forward(self, own: th.Tensor, tasks: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        own_per_task = own.unsqueeze(1).expand(-1, tasks.shape[1], -1)
        embedded = self.encode(th.cat([tasks, own_per_task], dim=-1))                 # (B, M, H)
        pooled = th.cat([embedded.mean(dim=1), embedded.amax(dim=1)], dim=-1)         # (B, 2H)
        return embedded, self.context(pooled)


class PoolingBody(nn.Module):
    """SB3 ``mlp_extractor``: features → (masked logits ``[pass, bid_0..M−1, quit_0..M−1]``, critic latent)."""

    def __init__(self, own_size: int, task_size: int, n_actions: int, hidden: int = 64) -> None:
        super().__init__()
        self.own_size, self.task_size = own_size, task_size
        self.actor = PoolingEncoder(own_size, task_size, hidden)
        self.critic = PoolingEncoder(own_size, task_size, hidden)
        self.task_head = mlp([2 * hidden, hidden, 2], activate_last=False)
        self.pass_head = nn.Linear(hidden, 1)
        self.latent_dim_pi = n_actions      # the logits themselves; the policy's action_net is the identity
        self.latent_dim_vf = hidden

    def output_layers(self) -> list[nn.Linear]:
        return [self.task_head[-1], self.pass_head]

    def forward(self, features: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        return self.forward_actor(features), self.forward_critic(features)

    def forward_actor(self, features: th.Tensor) -> th.Tensor:
        own, tasks, mask = split_features(features, self.own_size, self.task_size)
        embedded, context = self.actor(own, tasks)
        per_task = self.task_head(th.cat([embedded, context.unsqueeze(1).expand_as(embedded)], dim=-1))  # (B, M, 2)
        logits = th.cat([self.pass_head(context), per_task[..., 0], per_task[..., 1]], dim=-1)
        return logits.masked_fill(~mask, MASKED_LOGIT)

    def forward_critic(self, features: th.Tensor) -> th.Tensor:
        own, tasks, _ = split_features(features, self.own_size, self.task_size)
        return self.critic(own, tasks)[1]


class MlpBody(nn.Module):
    """SB3 ``mlp_extractor``: a plain MLP on the flat observation, masked logits out (fixed number of tasks)."""

    def __init__(self, obs_size: int, n_actions: int, hidden: int = 256) -> None:
        super().__init__()
        self.obs_size = obs_size
        self.actor = mlp([obs_size, hidden, hidden, n_actions], activate_last=False)
        self.critic = mlp([obs_size, hidden, hidden])
        self.latent_dim_pi = n_actions
        self.latent_dim_vf = hidden

    def output_layers(self) -> list[nn.Linear]:
        return [self.actor[-1]]

    def forward(self, features: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        return self.forward_actor(features), self.forward_critic(features)

    def forward_actor(self, features: th.Tensor) -> th.Tensor:
        obs, mask = features[:, : self.obs_size], features[:, self.obs_size:] > 0.5
        if mask.shape[-1] != self.actor[-1].out_features:
            raise ValueError(f"the mlp body was built for {self.actor[-1].out_features} actions, got {mask.shape[-1]}")
        return self.actor(obs).masked_fill(~mask, MASKED_LOGIT)

    def forward_critic(self, features: th.Tensor) -> th.Tensor:
        return self.critic(features[:, : self.obs_size])


class _TaskNetMixin:
    """Builds the body instead of SB3's MLP extractor and makes the action net the identity."""

    def __init__(self, observation_space: gym.spaces.Dict, action_space: gym.spaces.Discrete, lr_schedule: Any,
                 body: str = "pooling", hidden: int = 64, task_size: int = len(TASK_FEATURES), **kwargs: Any) -> None:
        if body not in BODIES:
            raise ValueError(f"body {body!r} is not one of {BODIES}")
        self.body, self.hidden, self.task_size = body, hidden, task_size
        kwargs.setdefault("features_extractor_class", MaskedObsExtractor)
        super().__init__(observation_space, action_space, lr_schedule, **kwargs)  # type: ignore[call-arg]

    def _build_mlp_extractor(self) -> None:
        obs_size = self.observation_space["observation"].shape[0]
        n_actions = int(self.action_space.n)
        if self.body == "pooling":
            own_size = obs_size - (n_actions - 1) // 2 * self.task_size
            self.mlp_extractor = PoolingBody(own_size, self.task_size, n_actions, self.hidden)
        else:
            self.mlp_extractor = MlpBody(obs_size, n_actions, self.hidden)

    def _build(self, lr_schedule: Any) -> None:
        super()._build(lr_schedule)  # type: ignore[misc]
        self.action_net = nn.Identity()
        for layer in self.mlp_extractor.output_layers():
            nn.init.orthogonal_(layer.weight, gain=0.01)
            nn.init.zeros_(layer.bias)
        self.optimizer = self.optimizer_class(self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()  # type: ignore[misc]
        data.update(body=self.body, hidden=self.hidden, task_size=self.task_size)
        return data


class TaskMaskablePolicy(_TaskNetMixin, MaskableActorCriticPolicy):
    """The policy for sb3-contrib's ``MaskablePPO``."""


class TaskPolicy(_TaskNetMixin, ActorCriticPolicy):
    """The policy for SB3's ``PPO`` (masking inside the network)."""


def masked_logits(policy: ActorCriticPolicy, observation: np.ndarray, action_mask: np.ndarray) -> th.Tensor:
    """Masked logits for a batch of raw observations; works for any number of tasks with the pooling body."""
    features = th.as_tensor(np.concatenate([observation, action_mask], axis=-1), dtype=th.float32,
                            device=policy.device)
    with th.no_grad():
        return policy.mlp_extractor.forward_actor(features)


def count_parameters(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())
