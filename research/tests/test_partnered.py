"""MAPPO with a partner (``research.training.partnered``): a round-0 planner plays round 0 and the actor the rest, or
the reverse; the checkpoint loads as the pair; a run started from a planner starts from its rule."""

from __future__ import annotations

import numpy as np
import pytest
from test_mappo import model_for  # tests/, on the path through research/tests/conftest.py

from research.policies.handover import Handover
from research.policies.round_zero import RoundZeroPlanner
from research.training import partnered
from taskalloc.evaluation.seeds import VALIDATION_SEED_START
from taskalloc.policies import make_policy, rollout
from taskalloc.policies.learned import LearnedPolicy
from taskalloc.policies.networks import masked_logits
from taskalloc.training import mappo
from taskalloc.training.critic import StateCritic
from taskalloc_env import ConfigError, TaskAllocEnv

ENV = {"scenario": "train_small", "task_quitting": True, "delta": 1}


def small_config(**fields) -> partnered.PartneredConfig:
    cfg = partnered.PartneredConfig(hidden=32, heads=2, layers=1, **fields)
    cfg.check()
    return cfg


# -- a bidder for after a planned round 0 (round_zero) ---------------------------------------------------------------
PLANNER = "learned:planner_small_attention"


def test_with_round_zero_the_actor_takes_over_where_the_planner_ends_round_0():
    """The group plays the planner's round 0 itself: the actor's first state is the state a plain env reaches
    after the planner's round 0 on the same instance, and no state the actor acts on is of round 0, in the first
    episode or in the ones after it."""
    cfg = small_config(round_zero=PLANNER)
    partner = partnered.load_partner(cfg)
    planner = partner.policy
    group = mappo.Group({"scenario": "train_small", "copies": 2}, cfg.env_overrides, cfg.max_cycles, 5, partner)
    group.reset()
    round_column = group.layout.own_names.index("round")
    for copy, seed in enumerate((5, 6)):
        env = TaskAllocEnv(**ENV)
        obs, infos = env.reset(seed=seed)
        planner.start(env)
        steps = 0
        while infos["uav_0"]["round"] == 0:
            obs, _, _, _, infos = env.step(planner.act(obs, infos))
            steps += 1
        assert steps > 1 and env.unwrapped.evaluate().score > 0, "the planner bids in round 0"
        np.testing.assert_array_equal(group.states[copy], env.state())
        np.testing.assert_array_equal(group.obs[copy], np.stack([obs[a]["observation"] for a in env.agents]))
    r = mappo.collect(model_for(group, cfg), group, n_steps=60, gamma=1.0, gae_lambda=1.0)
    assert len(group.scores) >= 2, "episodes ended and new ones began within 60 steps"
    assert (r.obs[:, round_column] > 0).all()      # the column is the round, scaled: 0 only in round 0
    # without a planner the actor starts every episode at round 0
    plain = mappo.Group({"scenario": "train_small", "copies": 1}, cfg.env_overrides, cfg.max_cycles, 5)
    plain.reset()
    assert (plain.obs[..., round_column] == 0).all()


def test_a_bidder_trained_after_a_planner_loads_as_the_pair(tmp_path):
    cfg = small_config(round_zero=PLANNER)
    partner = partnered.load_partner(cfg)
    group = mappo.Group({"scenario": "train_small"}, cfg.env_overrides, cfg.max_cycles, 0, partner)
    model = model_for(group, cfg)
    model.actor.eval()
    path = mappo.save_actor(tmp_path / "model", model.actor, group, cfg, partner.meta)
    pair = make_policy(f"learned:{path}")
    assert isinstance(pair, Handover) and isinstance(pair.first, RoundZeroPlanner) and pair.rounds == 1
    assert isinstance(pair.then, LearnedPolicy) and pair.name == f"learned:{path}"
    played = mappo.as_played(mappo.as_learned(model.actor, group, cfg), partner)
    env = TaskAllocEnv("train_small", invalid_action="raise", **pair.env_overrides)
    for seed in (VALIDATION_SEED_START, VALIDATION_SEED_START + 1):
        assert rollout(env, pair, seed=seed).score == rollout(env, played, seed=seed).score
    # meta round_zero must name a planner
    for bad in ({"round_zero": "learned:mappo_small_pooling_1m"}, {"round_zero": "cbgabi"}, {"round_zero": 3},
                {"round_zero": PLANNER, "then": "cbgabi"}, {"then": "no_such_policy"}):
        mappo.save_actor(tmp_path / "bad", model.actor, group, cfg, {"algo": partnered.PARTNERED, **bad})
        with pytest.raises(ConfigError, match=r"round_zero|then"):
            make_policy(f"learned:{tmp_path / 'bad.json'}")


def test_round_zero_must_be_a_planner_that_plays_with_the_run(tmp_path, capsys):
    from taskalloc_env.errors import run_cli

    for value, message in (("cbgabi", "not a round-0 planner"), ("learned:mappo_small_pooling_1m",
                                                                 "not a round-0 planner"),
                           ("learned:no_such_model", "no_such_model")):
        with pytest.raises(ConfigError, match=message):
            partnered.load_partner(small_config(round_zero=value))
    with pytest.raises(ConfigError, match="plays with"):
        partnered.load_partner(small_config(round_zero=PLANNER, env_overrides={"task_quitting": False}))
    for overrides in ({"task_quitting": False}, {}):       # a different value, or none at all
        with pytest.raises(ConfigError, match="plays with"):
            partnered.load_partner(small_config(later_rounds="cbgabi", env_overrides=overrides))
    with pytest.raises(ConfigError, match="unknown policy"):
        partnered.load_partner(small_config(later_rounds="cbgx"))
    with pytest.raises(ConfigError, match="at most one"):
        small_config(round_zero=PLANNER, later_rounds="cbgabi")
    assert run_cli(lambda: partnered.main(["--out-dir", str(tmp_path), "--round-zero", "cbgabi"])) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_a_run_with_round_zero_saves_a_checkpoint_that_loads_as_the_pair(tmp_path):
    summary = partnered.main(["--out-dir", str(tmp_path), "--round-zero", PLANNER, "--actor", "pooling",
                              "--hidden", "32", "--total-steps", "0", "--eval-episodes", "2"])
    pair = make_policy(f"learned:{tmp_path}")
    assert isinstance(pair, Handover) and isinstance(pair.first, RoundZeroPlanner)
    assert pair.then.meta["round_zero"] == PLANNER
    # eval.csv measured the pair: the same score on the same validation seeds
    env = TaskAllocEnv("train_small", **pair.env_overrides)
    seeds = (VALIDATION_SEED_START, VALIDATION_SEED_START + 1)
    ratio = np.mean([rollout(env, pair, seed=s).score for s in seeds]) / np.mean(
        [rollout(env, make_policy("cbgabi"), seed=s).score for s in seeds])
    assert summary["validation_ratio"]["train_small"] == pytest.approx(ratio)



def test_with_later_rounds_the_actor_plays_round_0_and_its_return_is_the_whole_score():
    """The partner plays every round after round 0 inside the group: the actor acts only on round-0 states, and
    with λ = γ = 1 the return at an episode's first step is its final score / (c̄·N), the partner's rounds
    included."""
    cfg = small_config(later_rounds="cbgabi")
    partner = partnered.load_partner(cfg)
    assert not partner.round_zero and partner.plays(1) and not partner.plays(0)
    group = mappo.Group({"scenario": "train_small", "copies": 1}, cfg.env_overrides, cfg.max_cycles, 0, partner)
    group.reset()
    r = mappo.collect(model_for(group, cfg), group, n_steps=30, gamma=1.0, gae_lambda=1.0)
    assert (r.obs[:, group.layout.own_names.index("round")] == 0).all()
    assert len(group.scores) >= 2, "round 0 of train_small takes a few steps"
    assert float(r.returns[0]) == pytest.approx(group.scores[0] / group.reward_scale, abs=1e-4)
    # the run's policy as it plays, and as its checkpoint loads: the actor in round 0, then the partner
    played = mappo.as_played(mappo.as_learned(group_actor := model_for(group, cfg).actor, group, cfg), partner)
    assert isinstance(played, Handover) and played.then is partner.policy and played.first.actor is group_actor


def test_init_from_a_planner_starts_from_its_rule():
    """From a planner's checkpoint the pass logit is 0, so on round-0 states the arg-max of the actor's policy is
    the planner's rule at threshold ½: the likeliest allowed task while p ≥ ½, else pass."""
    cfg = partnered.PartneredConfig(later_rounds="learned:mappo_small_pooling_1m", init_from="planner_small_attention")
    group = mappo.Group({"scenario": "train_small"}, cfg.env_overrides, cfg.max_cycles, 0)
    model = mappo.ActorCritic(mappo.make_actor(cfg, group.layout.own_size, group.layout.task_size),
                              StateCritic(group.n_equipment, cfg.hidden, cfg.heads))
    assert mappo.load_weights(model, cfg.init_from, partnered.Hook()) == ["actor"]
    planner = make_policy(PLANNER).first
    env = TaskAllocEnv(**ENV)
    compared = bids = 0
    for seed in range(VALIDATION_SEED_START, VALIDATION_SEED_START + 10):
        obs, infos = env.reset(seed=seed)
        planner.start(env)
        while env.agents and infos["uav_0"]["round"] == 0:
            stacked = np.stack([o["observation"] for o in obs.values()])
            masks = np.stack([o["action_mask"] for o in obs.values()])
            logits = masked_logits(model.actor, stacked, masks).numpy()
            assert (logits[:, 0] == 0).all()
            rule = planner.decide(stacked, masks)
            np.testing.assert_array_equal(logits.argmax(axis=1), rule)
            compared, bids = compared + len(rule), bids + int((rule > 0).sum())
            obs, _, _, _, infos = env.step(planner.act(obs, infos))
    assert bids > 10 and compared > bids, "both bids and passes were compared"
