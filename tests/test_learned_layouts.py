"""Committed learned models on environments whose observation has mode-dependent task features they never saw.

A faulty network adds ``member_silence`` and pop-up tasks add ``released`` to every task's block
(``taskalloc_env.observation``); ``LearnedPolicy`` selects the checkpoint's columns by name and drops only those.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("safetensors")

from taskalloc.policies import make_policy, rollout
from taskalloc.policies.learned import LearnedPolicy, feature_columns
from taskalloc_env import TaskAllocEnv
from taskalloc_env.observation import ObservationLayout

MODELS = ("train_small", "mappo_small_pooling_1m")

# produced by the code before column selection (commit 0f249f0), perfect network, scenario train_small:
# (model, seed) -> (paths, score, rounds)
BEFORE = {
    ("train_small", 0): ([[3, 4, 1, 5], [4, 1, 5], [0, 2, 6], [0, 7, 6]], 1121.77369366, 5),
    ("train_small", 1): ([[7, 5, 1], [6, 2, 3], [5, 1], [4, 6, 2, 3]], 1163.909157853, 4),
}


@pytest.mark.parametrize(("model", "seed"), sorted(BEFORE))
def test_perfect_network_actions_are_unchanged(model, seed):
    policy = make_policy(f"learned:{model}")
    alloc = rollout(TaskAllocEnv("train_small", **policy.env_overrides), policy, seed=seed)
    paths, score, rounds = BEFORE[model, seed]
    assert policy.columns is None                     # the observation is used as it is
    assert [list(p) for p in alloc.paths] == paths
    assert alloc.counters.rounds == rounds
    assert round(alloc.score, 9) == score


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("extra", [{"message_loss": 0.2}, {"popup_tasks": 2, "popup_period": 3},
                                   {"message_loss": 0.2, "popup_tasks": 2, "popup_period": 3}])
def test_committed_models_run_on_faulty_networks_and_popup_tasks(model, extra):
    policy = make_policy(f"learned:{model}")
    env = TaskAllocEnv("train_small", **extra, **policy.env_overrides)
    for seed in range(2):
        alloc = rollout(env, policy, seed=seed)
        assert alloc.converged and alloc.score > 0
    layout = env.observation_layout
    assert len(layout.task_names) == len(policy.task_features) + len(extra) - ("popup_period" in extra)
    assert policy.columns is not None and len(policy.columns) == (
        layout.own_size + layout.n_tasks * len(policy.task_features))


def test_selected_columns_are_the_checkpoints_features_by_name():
    """The actor's input under message loss equals the perfect-network layout's columns of the same values."""
    policy = make_policy("learned:train_small")
    env = TaskAllocEnv("train_small", message_loss=0.2, **policy.env_overrides)
    obs, _ = env.reset(seed=3)
    policy.start(env, 3)
    layout = env.observation_layout
    row = obs["uav_0"]["observation"]
    picked = row[policy.columns]
    _, tasks = layout.split(row)
    narrow = ObservationLayout(layout.n_tasks, layout.n_equipment, policy.task_features)
    _, picked_tasks = narrow.split(picked)
    for k, name in enumerate(policy.task_features):
        np.testing.assert_array_equal(picked_tasks[:, k], tasks[:, layout.task_column(name)])


def test_missing_or_unknown_features_are_still_refused():
    policy = make_policy("learned:train_small")
    needs_silence = LearnedPolicy(policy.actor, policy.own_features, (*policy.task_features, "member_silence"),
                                  policy.env_overrides, name="needs_silence")
    with pytest.raises(ValueError, match="trained on other observation features"):
        needs_silence.start(TaskAllocEnv("train_small", **policy.env_overrides), 0)
    layout = TaskAllocEnv("train_small").observation_layout
    other = dataclasses.replace(layout, task_names=(*layout.task_names, "not_optional"))
    assert feature_columns(other, policy.own_features, policy.task_features) is False
    dropped = dataclasses.replace(layout, task_names=layout.task_names[1:])
    assert feature_columns(dropped, policy.own_features, policy.task_features) is False
    assert feature_columns(layout, (*policy.own_features, "equipment_9"), policy.task_features) is False
