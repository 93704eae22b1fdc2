"""The RLlib env creator's config (``taskalloc_env.wrappers.rllib.make_env``), without Ray: keywords or a suite task."""

from __future__ import annotations

import pytest

from taskalloc_env import ConfigError, suite
from taskalloc_env.wrappers.rllib import make_env


def test_a_suite_task_gives_that_tasks_instances_with_rllibs_keys():
    env = make_env({"task": "taskalloc/Small-v0"})
    obs, _ = env.reset(seed=50_000)
    first = obs[env.possible_agents[0]]
    assert set(first) == {"observations", "action_mask"}
    plain = suite.task("taskalloc/Small-v0").config()
    assert env.unwrapped.config == plain


def test_keywords_override_the_task_and_plain_keywords_work():
    env = make_env({"task": "taskalloc/Small-v0", "max_cycles": 7})
    assert env.unwrapped.max_cycles == 7
    assert make_env({"scenario": "train_small"}).unwrapped.config.n_agents == 4


def test_an_unknown_task_lists_the_suite():
    with pytest.raises(ConfigError, match=r"unknown task 'taskalloc/Tiny-v0'.*taskalloc/Small-v0"):
        make_env({"task": "taskalloc/Tiny-v0"})
