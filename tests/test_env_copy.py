"""A deep copy or a pickle of an env mid-episode is an independent env that continues exactly as the original would:
the same observations, masks, rewards, terminations, infos, states and final allocation (search, MCTS and any user
that snapshots an env rely on it)."""

from __future__ import annotations

import copy
import pickle
import warnings

import numpy as np
import pytest
from helpers import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from taskalloc.evaluation.fuzz import draw_config
from taskalloc.policies import make_policy
from taskalloc_env import TaskAllocEnv

DUPLICATES = {"deepcopy": copy.deepcopy, "pickle": lambda env: pickle.loads(pickle.dumps(env))}


def assert_same(a, b, where: str) -> None:
    """Nested dicts of arrays and scalars, equal bit for bit."""
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for key in a:
            assert_same(a[key], b[key], f"{where}[{key}]")
    elif isinstance(a, (tuple, list)):
        assert len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f"{where}[{k}]")
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), where
    else:
        assert a == b, where


def play_on(env: TaskAllocEnv, observations: dict, seed: int) -> list:
    """Everything the env returns from here to the end, with the random masked policy seeded by ``seed``."""
    rng, returned = np.random.default_rng(seed), []
    while env.agents:
        actions = {a: int(rng.choice(np.flatnonzero(observations[a]["action_mask"]))) for a in env.agents}
        step = env.step(actions)
        observations = step[0]
        returned.append((*step, env.state()))
    returned.append(repr(env.evaluate()))
    return returned


def check_copy(config_seed: int, episode_seed: int, steps_before: int, policy_name: str, how: str) -> None:
    """Run ``steps_before`` steps of ``policy_name``, duplicate the env, run both on with the same actions."""
    rng, extra = np.random.default_rng(config_seed), np.random.default_rng([config_seed, 2])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = draw_config(rng, extra)
    policy = make_policy(policy_name)
    env = TaskAllocEnv(**config, **policy.env_overrides, max_cycles=30)
    observations, infos = env.reset(seed=episode_seed)
    policy.start(env, episode_seed)
    for _ in range(steps_before):
        if not env.agents:
            return
        observations, _, _, _, infos = env.step(policy.act(observations, infos))
    twin = DUPLICATES[how](env)
    theirs = play_on(twin, observations, episode_seed)
    ours = play_on(env, observations, episode_seed)
    assert len(ours) == len(theirs)
    for t, (mine, copied) in enumerate(zip(ours, theirs)):
        assert_same(mine, copied, f"step {t} after the copy ({how})")


@pytest.mark.parametrize("how", sorted(DUPLICATES))
@settings(max_examples=examples(100), deadline=None)
@given(config_seed=st.integers(0, 2**16), episode_seed=st.integers(0, 2**16), steps_before=st.integers(1, 8),
       policy_name=st.sampled_from(["random", "cbga", "cbgabi"]))
def test_a_copy_continues_as_the_original(how, config_seed, episode_seed, steps_before, policy_name):
    check_copy(config_seed, episode_seed, steps_before, policy_name, how)


def test_a_copy_is_independent_of_the_original():
    """Stepping the copy leaves the original's tables, round and next observations as they were."""
    env = TaskAllocEnv(n_agents=4, n_tasks=6)
    observations, _ = env.reset(seed=1)
    before = copy.deepcopy(env)
    twin = copy.deepcopy(env)
    while twin.agents:
        twin.step({a: int(np.flatnonzero(o["action_mask"])[-1]) for a, o in observations.items() if a in twin.agents})
        observations = {a: {"action_mask": np.r_[1, np.zeros(12, dtype=np.int8)]} for a in twin.agents}
    assert env.protocol.round == before.protocol.round == 0
    assert env.protocol.knowledge.groups == before.protocol.knowledge.groups
    assert_same(play_on(env, env._observations(), 5), play_on(before, before._observations(), 5), "original")
