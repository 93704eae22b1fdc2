"""Mixed teams: some agents played by scripted policies, the rest by the policy being trained or evaluated.

``scripted_agents`` maps agent names to policy names (``{"uav_0": "cbga"}``). One policy instance per name plays
all agents mapped to it; scripted policies here read only their own agents' observations (thesis Alg 5), so a
subset works.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from taskalloc.policies.base import Policy
from taskalloc.policies.registry import make_policy


def check_scripted_agents(scripted_agents: Mapping[str, str] | None, possible_agents: list[str]) -> dict[str, str]:
    """Validate ``scripted_agents`` against the env's agents; at least one agent must stay learned."""
    scripted = dict(scripted_agents or {})
    unknown = sorted(set(scripted) - set(possible_agents))
    if unknown:
        raise ValueError(f"scripted_agents names unknown agents {unknown}; agents are {possible_agents}")
    if len(scripted) >= len(possible_agents):
        raise ValueError("scripted_agents covers every agent; leave at least one agent to the learned policy")
    return scripted


def scripted_env_overrides(scripted_agents: Mapping[str, str] | None) -> dict[str, Any]:
    """The config fields the scripted teammates need from the environment (merged; conflicts raise)."""
    merged: dict[str, Any] = {}
    for name in sorted(set((scripted_agents or {}).values())):
        for key, value in make_policy(name).env_overrides.items():
            if key in merged and merged[key] != value:
                raise ValueError(f"scripted policies need conflicting env settings for {key!r}: "
                                 f"{merged[key]!r}, {value!r}")
            merged[key] = value
    return merged


class ScriptedTeammates:
    """The scripted agents of one environment copy: one policy instance per policy name."""

    def __init__(self, scripted_agents: Mapping[str, str]) -> None:
        self.assignment = dict(scripted_agents)
        self.policies = {name: make_policy(name) for name in sorted(set(self.assignment.values()))}

    def start(self, env: Any, seed: int | None) -> None:
        for policy in self.policies.values():
            policy.start(env, seed)

    def act(self, observations: Mapping[str, Any], infos: Mapping[str, Any] | None) -> dict[str, int]:
        actions: dict[str, int] = {}
        for name, policy in self.policies.items():
            own = {a: o for a, o in observations.items() if self.assignment.get(a) == name}
            if own:
                actions.update(policy.act(own, {a: (infos or {}).get(a, {}) for a in own}))
        return actions


class MixedTeamPolicy(Policy):
    """``learned`` plays every agent not in ``scripted_agents``; the scripted policies play the others."""

    def __init__(self, learned: Policy, scripted_agents: Mapping[str, str]) -> None:
        super().__init__()
        self.learned = learned
        self.scripted = ScriptedTeammates(scripted_agents)
        names = ", ".join(f"{a}={p}" for a, p in sorted(scripted_agents.items()))
        self.name = f"{learned.name}[{names}]"

    @property
    def env_overrides(self) -> dict[str, Any]:
        merged = dict(self.learned.env_overrides)
        for key, value in scripted_env_overrides(self.scripted.assignment).items():
            if key in merged and merged[key] != value:
                raise ValueError(f"learned and scripted policies need different {key!r}: {merged[key]!r}, {value!r}")
            merged[key] = value
        return merged

    def start(self, env: Any, seed: int | None = None) -> None:
        super().start(env, seed)
        check_scripted_agents(self.scripted.assignment, env.unwrapped.possible_agents)
        self.learned.start(env, seed)
        self.scripted.start(env, None if seed is None else seed + 1)

    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        learned_obs = {a: o for a, o in observations.items() if a not in self.scripted.assignment}
        actions = self.learned.act(learned_obs, {a: (infos or {}).get(a, {}) for a in learned_obs})
        actions.update(self.scripted.act(observations, infos))
        return actions


def with_teammates(policy: Policy, scripted_agents: Mapping[str, str] | None) -> Policy:
    """``policy`` for every agent, or a mixed team when ``scripted_agents`` is non-empty."""
    return MixedTeamPolicy(policy, scripted_agents) if scripted_agents else policy
