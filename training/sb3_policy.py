"""The actor networks of ``taskalloc.policies.networks`` inside SB3 / sb3-contrib actor-critic policies, for PPO
training.

SB3's features extractor only concatenates ``observation`` and ``action_mask``; the body (SB3's ``mlp_extractor``)
holds the actor (``pi``, one of ``taskalloc.policies.networks.NETWORKS``) and a critic of the same shape, and outputs
the masked logits, so the policy's ``action_net`` is the identity. The mask is applied inside the network (invalid
actions get ``MASKED_LOGIT``), so plain PPO never samples an invalid action; MaskablePPO masks again, which changes
nothing. Actor and critic have separate encoders. A trained policy's actor is ``actor_of(policy)``, which is what a
checkpoint stores (``taskalloc.policies.checkpoint``). With the environment's ``release_actions`` the policy is built
with ``kinds=3`` (``taskalloc.policies.networks``: bid, quit and release logits per task), which ``taskalloc train``
passes in ``policy_kwargs``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import torch as th
from sb3_contrib.common.maskable.policies import MaskableActorCriticPolicy
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from taskalloc.policies import checkpoint
from taskalloc.policies.learned import LearnedPolicy, resolve
from taskalloc.policies.networks import MlpActor, PoolingActor, PoolingEncoder, check_kinds, mlp, split_tasks
from taskalloc_env.observation import TASK_FEATURES, ObservationLayout

BODIES = ("pooling", "mlp")


class MaskedObsExtractor(BaseFeaturesExtractor):
    """``Dict(observation, action_mask)`` → ``[observation | action_mask]`` (no parameters)."""

    def __init__(self, observation_space: gym.spaces.Dict) -> None:
        width = observation_space["observation"].shape[0] + observation_space["action_mask"].shape[0]
        super().__init__(observation_space, features_dim=width)

    def forward(self, observations: dict[str, th.Tensor]) -> th.Tensor:
        return th.cat([observations["observation"].float(), observations["action_mask"].float()], dim=-1)


class Body(nn.Module):
    """SB3 ``mlp_extractor``: features ``[observation | mask]`` → (masked logits, critic latent)."""

    def __init__(self, pi: nn.Module, critic: nn.Module, n_actions: int, latent_dim_vf: int) -> None:
        super().__init__()
        self.pi, self.critic = pi, critic
        self.latent_dim_pi = n_actions      # the logits themselves; the policy's action_net is the identity
        self.latent_dim_vf = latent_dim_vf

    def _split(self, features: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        if isinstance(self.pi, MlpActor):
            n_actions = self.pi.n_actions
        else:                      # pooling, any M: width = own + M·F + 1 + K·M
            n_tasks = (features.shape[-1] - self.pi.own_size - 1) // (self.pi.task_size + self.pi.kinds)
            n_actions = self.pi.action_width(n_tasks)
        return features[:, :-n_actions], features[:, -n_actions:] > 0.5

    def forward(self, features: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        return self.forward_actor(features), self.forward_critic(features)

    def forward_actor(self, features: th.Tensor) -> th.Tensor:
        observation, mask = self._split(features)
        return self.pi(observation, mask)

    def forward_critic(self, features: th.Tensor) -> th.Tensor:
        observation, _ = self._split(features)
        if isinstance(self.critic, PoolingEncoder):
            return self.critic(*split_tasks(observation, self.pi.own_size, self.pi.task_size))[1]
        return self.critic(observation)


class _TaskNetMixin:
    """Builds the body instead of SB3's MLP extractor and makes the action net the identity."""

    def __init__(self, observation_space: gym.spaces.Dict, action_space: gym.spaces.Discrete, lr_schedule: Any,
                 body: str = "pooling", hidden: int = 64, task_size: int = len(TASK_FEATURES), kinds: int = 2,
                 **kwargs: Any) -> None:
        if body not in BODIES:
            raise ValueError(f"body {body!r} is not one of {BODIES}")
        check_kinds(kinds)
        self.body, self.hidden, self.task_size, self.kinds = body, hidden, task_size, kinds
        kwargs.setdefault("features_extractor_class", MaskedObsExtractor)
        super().__init__(observation_space, action_space, lr_schedule, **kwargs)  # type: ignore[call-arg]

    def _build_mlp_extractor(self) -> None:
        obs_size = self.observation_space["observation"].shape[0]
        n_actions = int(self.action_space.n)
        if self.body == "pooling":
            own_size = obs_size - (n_actions - 1) // self.kinds * self.task_size
            pi = PoolingActor(own_size, self.task_size, self.hidden, self.kinds)
            self.mlp_extractor = Body(pi, PoolingEncoder(own_size, self.task_size, self.hidden), n_actions,
                                      self.hidden)
        else:
            pi = MlpActor(obs_size, n_actions, self.hidden)
            self.mlp_extractor = Body(pi, mlp([obs_size, self.hidden, self.hidden]), n_actions, self.hidden)

    def _build(self, lr_schedule: Any) -> None:
        super()._build(lr_schedule)  # type: ignore[misc]
        self.action_net = nn.Identity()
        for layer in self.mlp_extractor.pi.output_layers():
            nn.init.orthogonal_(layer.weight, gain=0.01)
            nn.init.zeros_(layer.bias)
        self.optimizer = self.optimizer_class(self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()  # type: ignore[misc]
        data.update(body=self.body, hidden=self.hidden, task_size=self.task_size, kinds=self.kinds)
        return data


class TaskMaskablePolicy(_TaskNetMixin, MaskableActorCriticPolicy):
    """The policy for sb3-contrib's ``MaskablePPO``."""


class TaskPolicy(_TaskNetMixin, ActorCriticPolicy):
    """The policy for SB3's ``PPO`` (masking inside the network)."""


def actor_of(policy: ActorCriticPolicy) -> nn.Module:
    """The actor network of a policy built here (what a checkpoint stores)."""
    return policy.mlp_extractor.pi


def protocol_overrides(env_kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """The options a policy plays by among an env's keyword arguments (``checkpoint.POLICY_OPTIONS``: what a learned
    policy needs from its env; the network, the round bound and the instance are the run's)."""
    return {k: v for k, v in env_kwargs.items() if k in checkpoint.POLICY_OPTIONS}


def as_learned(policy: ActorCriticPolicy, layout: ObservationLayout, env_kwargs: Mapping[str, Any],
               name: str = "learned") -> LearnedPolicy:
    """The SB3 policy's actor behind the ``Policy`` interface (greedy), for evaluation during training."""
    return LearnedPolicy(actor_of(policy), layout.own_names, layout.task_names, protocol_overrides(env_kwargs),
                         name=name)


def save_checkpoint(stem: Path, policy: ActorCriticPolicy, layout: ObservationLayout, env_kwargs: Mapping[str, Any],
                    meta: Mapping[str, Any]) -> Path:
    """Write the actor as a checkpoint (``taskalloc.policies.checkpoint``); returns the JSON path."""
    return checkpoint.save(stem, actor_of(policy), layout.own_names, layout.task_names,
                           protocol_overrides(env_kwargs), meta)


def load_actor_weights(policy: ActorCriticPolicy, source: str | Path) -> None:
    """Start from a checkpoint's actor weights (``init_from``); the critic keeps its initialisation."""
    loaded = checkpoint.load(resolve(source))
    try:
        actor_of(policy).load_state_dict(loaded.actor.state_dict(), strict=True)
    except RuntimeError as exc:
        raise ValueError(f"init_from {source}: its {loaded.network} network does not match this run's body "
                         f"({str(exc).splitlines()[0]})") from None
