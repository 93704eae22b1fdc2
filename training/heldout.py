"""Evaluate policies on fixed seeds: each policy in an environment built with its ``env_overrides``.

Seeds: held-out test seeds are ``10_000 … 10_099`` (the tables in ``docs/learning.md``); training's periodic
evaluation uses validation seeds ``20_000 …``; training instances come from the vector env's seeding (copy c of
a run with seed s starts from ``s + c``) and behaviour cloning's demonstrations from ``100_000 …``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from policies.base import Policy
from policies.rollout import rollout
from taskalloc_env.allocation import Allocation
from taskalloc_env.env import TaskAllocEnv
from training.teams import MixedTeamPolicy

TEST_SEEDS = range(10_000, 10_100)
VALIDATION_SEED_START = 20_000
DEMO_SEED_START = 100_000
SUMMARY_FIELDS = ("score", "valid_tasks", "rounds", "messages")


def with_teammates(policy: Policy, scripted_agents: Mapping[str, str] | None) -> Policy:
    """``policy`` for every agent, or a mixed team when ``scripted_agents`` is non-empty."""
    return MixedTeamPolicy(policy, scripted_agents) if scripted_agents else policy


def evaluate(policy: Policy, env_kwargs: Mapping[str, Any], seeds: Sequence[int]) -> list[Allocation]:
    """One episode per seed; the env gets ``env_kwargs`` plus the policy's ``env_overrides``."""
    env = TaskAllocEnv(**{**env_kwargs, **policy.env_overrides})
    return [rollout(env, policy, seed=int(seed)) for seed in seeds]


def summarise(allocations: Sequence[Allocation]) -> dict[str, float]:
    """Means of score, valid tasks, rounds and messages, plus the score's standard deviation."""
    rows = [a.summary() for a in allocations]
    out = {k: float(np.mean([r[k] for r in rows])) for k in SUMMARY_FIELDS}
    out["score_std"] = float(np.std([r["score"] for r in rows]))
    return out
