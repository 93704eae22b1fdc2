"""The direct solver (``taskalloc.policies.fast.solve``) reaches exactly the allocation, counters included, of an
episode."""

from __future__ import annotations

import numpy as np
import pytest

from taskalloc.evaluation.fuzz import draw_config
from taskalloc.policies import make_policy, rollout
from taskalloc.policies.fast import solvable, solve
from taskalloc_env import TaskAllocEnv, resolve_config

POLICIES = ("cbga", "cbga+tb", "cbga+tq", "cbgabi")


@pytest.mark.parametrize("name", [*POLICIES, "cbba"])
def test_direct_solve_equals_the_episode_on_the_default_scenario(name):
    overrides = {"agents_per_task": 1} if name == "cbba" else {}
    policy = make_policy(name)
    env = TaskAllocEnv("default", **overrides, **policy.env_overrides)
    for seed in range(4):
        episode = rollout(env, policy, seed=seed)
        assert solve(env.scenario, env.config, name) == episode


@pytest.mark.parametrize("sample", range(3))
def test_direct_solve_equals_the_episode_across_options(sample):
    rng, extra = np.random.default_rng(sample), np.random.default_rng([sample, 2])
    checked = 0
    while checked < 25:
        kw = draw_config(rng, extra)        # deterministic pop-up tasks (periodic or listed) included
        cfg = resolve_config("default", **kw)
        if not solvable(cfg):
            continue
        name = POLICIES[checked % len(POLICIES)]
        policy = make_policy(name)
        env = TaskAllocEnv(**kw, max_cycles=300, **policy.env_overrides)
        episode = rollout(env, policy, seed=checked)
        assert solve(env.scenario, env.config, name, max_cycles=300) == episode, kw
        checked += 1


def test_direct_solve_refuses_what_it_cannot_reproduce():
    cfg = resolve_config("train_small", message_loss=0.1)
    env = TaskAllocEnv(cfg)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="perfect links"):
        solve(env.scenario, cfg, "cbga")
    with pytest.raises(ValueError, match="asynchronous consensus"):
        solve(env.scenario, resolve_config("train_small", agents_per_task=1, consensus="acbba"), "cbba")
    with pytest.raises(ValueError, match="scripted consensus"):
        solve(env.scenario, resolve_config("train_small"), "random")
