"""The environments of a MAPPO run (``taskalloc.training.mappo``): the env copies of one mixture entry stepped together,
and the optional partner that plays the rounds the actor does not learn (ours), with the hook that supplies it."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from torch import nn

from taskalloc.policies.base import Policy, stack_observations
from taskalloc_env.config import resolve_config
from taskalloc_env.env import TaskAllocEnv
from taskalloc_env.vector import vector_env


# -- environments: one group of copies per mixture entry ----------------------------------------------------------
class Partner(Protocol):
    """A fixed policy that plays the rounds the actor does not learn, as part of the environment's dynamics."""

    policy: Policy
    meta: Mapping[str, Any]         # what the actor's checkpoint records about its partner

    def plays(self, round_: int) -> bool:
        """Whether the partner plays this protocol round (``info["round"]``)."""

    def with_actor(self, bidder: Policy) -> Policy:
        """The actor as it plays, with its partner (what its checkpoint loads as)."""


class PartnerHook(Protocol):
    """What a caller plugs into the loop (ours): the config class (``MappoConfig`` with its own fields), where its
    config names resolve, its partner, and how an actor started from a checkpoint (``init_from``) is adjusted."""

    config: type[Any]               # taskalloc.training.mappo.MappoConfig or a subclass
    configs: Path | None
    prog: str

    def partner(self, cfg: Any) -> Partner | None:
        """The run's partner, checked against ``cfg`` (``ConfigError``), or ``None``."""

    def init_actor(self, actor: nn.Module, meta: Mapping[str, Any]) -> None:
        """Adjust ``actor`` just loaded from a checkpoint with this ``meta``."""


class Group:
    """The env copies of one mixture entry (one size), stepped together; rewards in units of c̄ · N.

    Without a partner the copies are the instances of one batched env (``taskalloc_env.vector_env``, same-step
    autoreset: the same episodes as separate copies, without the dict API); with a partner, separate envs, because
    the partner's policies act on each env's dict observations."""

    def __init__(self, entry: Mapping[str, Any], env_overrides: Mapping[str, Any], max_cycles: int,
                 first_seed: int, partner: Partner | None = None) -> None:
        self.label = str(entry.get("label") or entry["scenario"])
        self.partner = partner
        self.from_steps = int(entry.get("from_steps", 0))
        config = resolve_config(entry["scenario"], **dict(entry.get("overrides") or {}))
        self.env_kwargs = {"scenario": config, **env_overrides}
        self.reward_scale = float(config.reward) * config.n_agents
        self.copies = int(entry.get("copies", 1))
        kwargs = {**self.env_kwargs, "max_cycles": max_cycles, "reward_scale": self.reward_scale}
        self.batch = vector_env(self.copies, autoreset_mode="same_step", **kwargs) if partner is None else None
        self.envs = (self.batch.envs if self.batch is not None
                     else [TaskAllocEnv(**kwargs) for _ in range(self.copies)])
        env = self.envs[0]
        self.agents = list(env.possible_agents)
        self.n_agents, self.n_tasks = config.n_agents, config.n_tasks
        self.kinds = (int(env.action_space(self.agents[0]).n) - 1) // self.n_tasks   # 2, or 3 with release actions
        self.layout = env.observation_layout
        self.n_equipment = self.layout.n_equipment
        self.first_seed = first_seed
        self.scores: list[float] = []
        self.obs = self.masks = self.states = np.empty(0)

    def reset(self) -> None:
        """Copy i starts from seed ``first_seed + i``; later episodes continue that copy's generator."""
        if self.batch is not None:
            obs, _ = self.batch.reset(seed=self.first_seed)
            self.obs, self.masks, self.states = obs["observation"], obs["action_mask"], self.batch.state()
            return
        rows = [self._observe(env, self._begin(env, self.first_seed + i)) for i, env in enumerate(self.envs)]
        self.obs, self.masks, self.states = (np.stack(x) for x in zip(*rows))

    def _begin(self, env: TaskAllocEnv, seed: int | None = None) -> Mapping[str, Any]:
        """A new episode's observations where the actor first acts: at the start, or after its partner's round 0
        (an episode that ends within it counts as played and is followed by the next)."""
        obs, infos = env.reset(seed=seed)
        if self.partner is None:
            return obs
        self.partner.policy.start(env)
        obs, infos, _, _ = self._partner_plays(env, obs, infos)
        if not env.agents:
            self.scores.append(infos[self.agents[0]]["score"])
            return self._begin(env)
        return obs

    def _partner_plays(self, env: TaskAllocEnv, obs: Mapping[str, Any], infos: Mapping[str, Any]
                       ) -> tuple[Mapping[str, Any], Mapping[str, Any], float, bool]:
        """The partner's steps while it plays the current round: the observations and infos where it stops, the
        team reward it earned, and whether max_cycles cut the episode there."""
        gain, cut = 0.0, False
        while env.agents and self.partner.plays(infos[self.agents[0]]["round"]):
            obs, reward, terminated, truncated, infos = env.step(self.partner.policy.act(obs, infos))
            gain += reward[self.agents[0]]
            cut = all(truncated.values()) and not all(terminated.values())
        return obs, infos, gain, cut

    def _observe(self, env: TaskAllocEnv, obs: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return (*stack_observations(obs, self.agents), env.state())

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[np.ndarray | None]]:
        """Step every copy (and the partner's rounds that follow); (rewards (C,), episode ends (C,), the last state
        of each copy cut by max_cycles)."""
        if self.batch is not None:
            return self._step_batch(actions)
        rewards, dones, cut = np.zeros(len(self.envs)), np.zeros(len(self.envs), dtype=bool), []
        for i, env in enumerate(self.envs):
            obs, reward, terminated, truncated, infos = env.step(dict(zip(self.agents, actions[i].tolist())))
            rewards[i] = reward[self.agents[0]]
            ended_by_limit = all(truncated.values()) and not all(terminated.values())
            if env.agents and self.partner is not None:     # the rest may be the partner's (later_rounds)
                obs, infos, gain, ended_by_limit = self._partner_plays(env, obs, infos)
                rewards[i] += gain
            cut.append(env.state() if ended_by_limit else None)
            if not env.agents:
                dones[i] = True
                self.scores.append(infos[self.agents[0]]["score"])
                obs = self._begin(env)
            self.obs[i], self.masks[i], self.states[i] = self._observe(env, obs)
        return rewards, dones, cut

    def _step_batch(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[np.ndarray | None]]:
        """``step`` on the batched env: one call for every copy."""
        obs, rewards, terminated, truncated, infos = self.batch.step(actions)
        dones = terminated | truncated
        cut: list[np.ndarray | None] = [None] * self.copies
        for k in np.flatnonzero(truncated & ~terminated).tolist():
            cut[k] = infos["final_state"][k]
        self.scores.extend(infos["final_info"]["score"][dones].tolist())
        self.obs, self.masks, self.states = obs["observation"], obs["action_mask"], self.batch.state()
        return rewards[:, 0].copy(), dones, cut
