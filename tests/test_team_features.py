"""``team_features``: what every agent knows of the team at launch, seen from each task (an observation option of
ours, off by default)."""

from __future__ import annotations

import numpy as np
import pytest

from taskalloc_env import TaskAllocEnv
from taskalloc_env.errors import ConfigError
from taskalloc_env.observation import TASK_FEATURES, TEAM_FEATURES
from taskalloc_env.scenario import Agent, Scenario, Task


def three_agents() -> Scenario:
    """Agents at x = 0, 1, 3 (the last twice as fast); tasks at x = 0.5 and x = 4."""
    agents = [Agent((0.0, 0.0, 0.0), 1.0), Agent((1.0, 0.0, 0.0), 1.0), Agent((3.0, 0.0, 0.0), 2.0)]
    tasks = [Task((0.5, 0.0, 0.0), 100.0, 0.0, 50.0, 1.0), Task((4.0, 0.0, 0.0), 100.0, 0.0, 50.0, 1.0)]
    return Scenario.from_entities(agents, tasks, arena=(5.0, 5.0, 2.0))


def test_the_default_observation_has_no_team_features():
    env = TaskAllocEnv("train_small")
    assert env.observation_layout.task_names == TASK_FEATURES


def test_team_features_by_hand():
    """Flight times to task 0 (x = 0.5): 0.5, 0.5, 1.25; to task 1 (x = 4): 4, 3, 0.5. Sooner agents are strictly
    sooner (a tie is not sooner); the nearest other agent's start distance is divided by the arena diagonal."""
    env = TaskAllocEnv(three_agents(), team_features=True)
    obs, _ = env.reset(seed=0)
    layout = env.observation_layout
    assert layout.task_names == TASK_FEATURES + TEAM_FEATURES
    sooner = np.array([layout.task_feature(obs[a]["observation"], "sooner_agents") for a in env.agents])
    nearest = np.array([layout.task_feature(obs[a]["observation"], "nearest_other") for a in env.agents])
    np.testing.assert_allclose(sooner, np.array([[0, 2], [0, 1], [2, 0]]) / 3)
    diagonal = np.linalg.norm([5.0, 5.0, 2.0])
    np.testing.assert_allclose(nearest, np.array([[0.5, 1.0], [0.5, 1.0], [0.5, 3.0]]) / diagonal, rtol=1e-6)


def test_a_lone_agent_sees_the_bound():
    agents = [Agent((0.0, 0.0, 0.0), 1.0)]
    tasks = [Task((1.0, 0.0, 0.0), 100.0, 0.0, 50.0, 1.0)]
    env = TaskAllocEnv(Scenario.from_entities(agents, tasks, arena=(5.0, 5.0, 2.0)), team_features=True)
    obs, _ = env.reset(seed=0)
    features = env.observation_layout.split(obs["uav_0"]["observation"])[1][0]
    names = env.observation_layout.task_names
    assert features[names.index("sooner_agents")] == 0.0
    assert features[names.index("nearest_other")] == 2.0


@pytest.mark.parametrize("scenario", ["train_small", "default"])
def test_team_features_stay_in_the_space_and_do_not_change_the_episode(scenario):
    """Every observation lies in the space; the allocation of a scripted episode is the same with and without."""
    from taskalloc.policies import make_policy, rollout

    for seed in range(3):
        allocations = []
        for team in (False, True):
            policy = make_policy("cbgabi")
            env = TaskAllocEnv(scenario, team_features=team, **policy.env_overrides)
            obs, _ = env.reset(seed=seed)
            assert all(env.observation_space(a).contains(o) for a, o in obs.items())
            allocations.append(rollout(env, policy, seed=seed))
        assert allocations[0].paths == allocations[1].paths
        assert allocations[0].score == allocations[1].score


@pytest.mark.parametrize("name", ["train_small", "mappo_small_pooling_1m"])
def test_a_model_trained_without_them_plays_the_same_with_them(name):
    """The team columns are dropped from the input of a checkpoint that never saw them (the way a round-0 planner
    trained with them hands over to such a bidder): its episodes are the same with and without the option."""
    from taskalloc.policies import make_policy, rollout

    for seed in range(3):
        allocations = []
        for team in (False, True):
            policy = make_policy(f"learned:{name}")
            env = TaskAllocEnv("train_small", team_features=team, **policy.env_overrides)
            allocations.append(rollout(env, policy, seed=seed))
            assert (policy.columns is None) is not team
        assert allocations[0].paths == allocations[1].paths
        assert allocations[0].score == allocations[1].score


def test_a_non_boolean_is_refused():
    with pytest.raises(ConfigError, match="team_features"):
        TaskAllocEnv("train_small", team_features="yes")
