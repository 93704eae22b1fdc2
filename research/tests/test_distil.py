"""The oracle's targets and the distillation of the optimum (``research.policies.oracle``,
``research.training.distil``)."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
import torch as th

from research.policies.oracle import OraclePolicy
from research.training import distil
from taskalloc.policies import make_policy, rollout
from taskalloc_env import ConfigError, TaskAllocEnv


def test_the_oracles_targets_are_allowed_actions_and_hold_its_own_choice():
    env = TaskAllocEnv("train_small", task_quitting=True, delta=1)
    oracle = OraclePolicy()
    agents = env.possible_agents
    for seed in range(4):
        observations, _ = env.reset(seed=seed)
        oracle.start(env, seed)
        while env.agents:
            masks = np.stack([observations[a]["action_mask"] for a in agents]).astype(bool)
            targets = oracle.targets(agents, masks)
            actions = oracle.act(observations)
            assert not (targets & ~masks).any()
            for row, agent in enumerate(agents):
                assert targets[row, actions[agent]]
                optimal = {1 + j for j in oracle.paths[row]}
                bids = set(np.flatnonzero(targets[row]).tolist()) - {0}
                assert bids == {a for a in optimal if masks[row, a]}
                assert targets[row, 0] == (not bids)
            observations, *_ = env.step(actions)


def test_the_set_loss_is_minus_the_log_of_the_probability_on_the_set():
    logits = th.tensor([[0.0, 1.0, 2.0], [3.0, 0.0, 0.0]])
    targets = th.tensor([[False, True, True], [True, False, False]])
    p = th.softmax(logits, dim=-1)
    expected = -(math.log(p[0, 1] + p[0, 2]) + math.log(p[1, 0])) / 2
    assert distil.set_loss(logits, targets).item() == pytest.approx(expected)


def test_a_bad_distillation_config_names_the_field():
    with pytest.raises(ConfigError, match="'actor'"):
        distil.DistilConfig(actor="mlp").check()
    with pytest.raises(ConfigError, match="'iterations'"):
        distil.DistilConfig(iterations=0).check()


@pytest.mark.slow
def test_a_short_distillation_agrees_with_the_oracle_more_than_cbgabi_and_saves_a_policy(tmp_path):
    """Two DAgger iterations on 40 instances each: the actor's greedy action is in the oracle's set more often than
    CBGABI's rule on the same validation states, and the saved actor plays as ``learned:<out_dir>``."""
    out = tmp_path / "run"
    distil.main(["--config", "distil_small", "--iterations", "2", "--episodes", "40", "--eval-episodes", "8",
                 "--out-dir", str(out)])
    with open(out / "distil.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["iteration"]) for r in rows] == [0, 1]
    assert float(rows[-1]["validation_agreement"]) > float(rows[-1]["cbgabi_agreement"])
    policy = make_policy(f"learned:{out}")
    allocation = rollout(TaskAllocEnv("train_small", **policy.env_overrides), policy, seed=0)
    assert allocation.converged and not allocation.conflicts
