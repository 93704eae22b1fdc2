"""Research's models and configs: each model loads by name after ``import research`` through the loader its meta
selects, the behaviour-cloning model plays as it did in the product, and every research config passes its checks."""

from __future__ import annotations

from pathlib import Path

import pytest

from research import CONFIGS, MODELS
from research.plugins import is_planner
from research.policies.handover import Handover
from research.policies.round_zero import RoundZeroPlanner
from taskalloc.policies import make_policy, rollout
from taskalloc.policies.learned import LearnedPolicy
from taskalloc_env import TaskAllocEnv

# (model, seed) -> (paths, score, rounds) on train_small, as measured in the product before the move
BEFORE = {
    ("train_small_bc", 0): ([[0, 7, 5], [0, 2, 5], [4, 1, 6], [3, 4, 1, 6]], 1153.289464932, 6),
    ("train_small_bc", 1): ([[6, 0, 3], [7, 2, 1], [2, 3], [4, 6, 1]], 1086.02291624, 6),
}


@pytest.mark.parametrize(("model", "seed"), sorted(BEFORE))
def test_the_behaviour_cloning_model_plays_as_before(model, seed):
    policy = make_policy(f"learned:{model}")
    alloc = rollout(TaskAllocEnv("train_small", **policy.env_overrides), policy, seed=seed)
    paths, score, rounds = BEFORE[model, seed]
    assert [list(p) for p in alloc.paths] == paths
    assert alloc.counters.rounds == rounds and round(alloc.score, 9) == score


def test_every_research_model_loads_by_name_through_its_loader():
    kinds = {name.name: make_policy(f"learned:{name.name}") for name in sorted(MODELS.iterdir())
             if (name / "model.json").is_file()}
    assert set(kinds) == {"mappo_after_planner_small", "mappo_small_pooling", "planner_default",
                          "planner_small_attention", "train_small_bc"}
    for name in ("planner_default", "planner_small_attention"):
        assert is_planner(kinds[name]) and isinstance(kinds[name].then, LearnedPolicy)
    pair = kinds["mappo_after_planner_small"]       # the planner's round 0, then the bidder trained after it
    assert isinstance(pair, Handover) and isinstance(pair.first, RoundZeroPlanner)
    assert isinstance(pair.then, LearnedPolicy) and not is_planner(pair.then)
    assert type(kinds["train_small_bc"]) is LearnedPolicy


@pytest.mark.parametrize("path", sorted(CONFIGS.glob("*.yaml")), ids=lambda p: p.stem)
def test_every_research_config_loads_and_passes_its_checks(path: Path, tmp_path):
    from research.training import distil, partnered, planner
    from taskalloc.training import mappo
    from taskalloc.training.config import parse

    argv = ["--config", path.stem, "--out-dir", str(tmp_path / "run")]
    if path.stem.startswith("mappo_"):
        cfg = mappo.load_config(argv, partnered.Hook())
    else:
        kind = distil.DistilConfig if path.stem.startswith("distil_") else planner.PlannerConfig
        cfg = parse(kind, argv, "research", None, configs=CONFIGS)
        cfg.check()
    assert cfg.name == path.stem and not (tmp_path / "run").exists()
