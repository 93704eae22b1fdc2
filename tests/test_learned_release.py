"""Learned actors with release heads (``kinds=3``, ``taskalloc.policies.networks``): the committed checkpoints
(``kinds=2``) play as before, a release actor plays only mask-valid actions and its logits sit in the codec's columns,
its checkpoint round-trips and carries ``release_actions``, and MAPPO and SB3 build it from the environment."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch as th

from taskalloc.policies import checkpoint, make_policy
from taskalloc.policies.checkpoint import CheckpointError
from taskalloc.policies.learned import LearnedPolicy, greedy_actions
from taskalloc.policies.networks import MASKED_LOGIT, AttentionActor, PoolingActor, masked_logits
from taskalloc.training import mappo
from taskalloc_env import TaskAllocEnv
from taskalloc_env.actions import (
    PASS,
    ActionKind,
    bid_columns,
    decode,
    encode_bid,
    encode_quit,
    encode_release,
    quit_columns,
    release_columns,
)

# observations from train_small episodes of mappo_small_pooling_1m (task_quitting, delta 1; four rows with a quit
# allowed), with every committed model's masked logits and greedy actions on them, computed before the actors had a
# ``kinds`` option
PINNED = Path(__file__).parent / "data" / "committed_model_logits.json"
MODELS = Path(__file__).parents[1] / "models"
OVERRIDES = {"task_quitting": True, "delta": 1, "release_actions": True}
RELEASE_ENV = {"scenario": "train_small", **OVERRIDES}


def release_actor(network: str, seed: int = 0) -> th.nn.Module:
    """A small release actor, its output layers away from zero so that the logits differ between actions."""
    th.manual_seed(seed)
    actor = (PoolingActor(7, 22, 16, kinds=3) if network == "pooling"
             else AttentionActor(7, 22, 16, heads=2, layers=1, kinds=3))
    with th.no_grad():
        for layer in actor.output_layers():
            layer.weight.normal_(0, 1.0)
    return actor.eval()


def observations(env_kwargs: dict, seeds: range, steps: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Rows of observations and masks from CBGA's episodes (the first ``steps`` steps of each)."""
    rows, masks = [], []
    for seed in seeds:
        env = TaskAllocEnv(**env_kwargs)
        obs, infos = env.reset(seed=seed)
        cbga = make_policy("cbga")
        cbga.start(env)
        for _ in range(steps):
            if not env.agents:
                break
            rows += [o["observation"] for o in obs.values()]
            masks += [o["action_mask"] for o in obs.values()]
            obs, _, _, _, infos = env.step(cbga.act(obs, infos))
    return np.stack(rows), np.stack(masks)


def test_the_committed_checkpoints_play_bit_identically():
    """Every committed model (no ``kinds`` in its JSON: 2) gives the pinned logits and greedy actions exactly (on one
    torch thread, as they were pinned: another thread count may sum in another order)."""
    threads = th.get_num_threads()
    th.set_num_threads(1)
    try:
        check_pinned_logits()
    finally:
        th.set_num_threads(threads)


def check_pinned_logits() -> None:
    pinned = json.loads(PINNED.read_text())
    obs = np.array(pinned["observation"], dtype=np.float32)
    masks = np.array(pinned["action_mask"], dtype=np.int8)
    assert set(pinned["models"]) == {"mappo_small_pooling_1m", "mappo_small", "train_small"}
    for name, expected in pinned["models"].items():
        policy = LearnedPolicy.load(name)
        spec = json.loads((MODELS / name / "model.json").read_text())
        assert "kinds" not in spec["network"]["config"] and policy.actor.kinds == 2
        np.testing.assert_array_equal(masked_logits(policy.actor, obs, masks).numpy(),
                                      np.array(expected["logits"], dtype=np.float32))
        assert policy.decide(obs, masks).tolist() == expected["greedy_actions"]


@pytest.mark.parametrize("network", ["pooling", "attention"])
def test_each_kind_of_logit_lands_in_its_codec_columns_and_is_masked(network):
    """With the last layer's kinds set apart (bid 1, quit 2, release 3), the logits of each kind sit in the columns
    of ``taskalloc_env.actions``; every column the mask forbids, release columns included, is ``MASKED_LOGIT``."""
    actor = release_actor(network)
    head = actor.task_head[-1]
    with th.no_grad():
        head.weight.zero_()
        head.bias.copy_(th.tensor([1.0, 2.0, 3.0]))
    obs, masks = observations(RELEASE_ENV, range(2))
    m = 8
    assert masks.shape[1] == 1 + 3 * m and masks[:, release_columns(m)].any()
    everything = masked_logits(actor, obs, np.ones_like(masks)).numpy()
    for columns, value in ((bid_columns(m), 1.0), (quit_columns(m), 2.0), (release_columns(m), 3.0)):
        np.testing.assert_array_equal(everything[:, columns], value)
    logits = masked_logits(actor, obs, masks).numpy()
    assert (logits[masks == 0] == MASKED_LOGIT).all()
    assert (logits[masks == 1] != MASKED_LOGIT).all()
    forbidden = masks[:, release_columns(m)] == 0
    assert forbidden.any() and (logits[:, release_columns(m)][forbidden] == MASKED_LOGIT).all()


def test_greedy_play_picks_the_most_likely_kind_among_four():
    """Release the likeliest kind: its best task; pass, bid and quit as before (``greedy_actions``)."""
    m = 3
    logits = np.full((4, 1 + 3 * m), -50.0)
    logits[0, PASS] = 5.0
    logits[1, encode_bid(2)] = 5.0
    logits[2, encode_quit(1, m)] = 5.0
    logits[3, [encode_release(0, m), encode_release(2, m)]] = [3.0, 4.0]
    logits[3, encode_bid(1)] = 3.5          # the likeliest single action, but the release kind is likelier
    probs = np.exp(logits - logits.max(axis=1, keepdims=True))
    probs /= probs.sum(axis=1, keepdims=True)
    assert greedy_actions(logits, probs, m).tolist() == [PASS, encode_bid(2), encode_quit(1, m),
                                                         encode_release(2, m)]


@pytest.mark.parametrize("network", ["pooling", "attention"])
@pytest.mark.parametrize("deterministic", [False, True])
def test_a_release_actor_plays_only_mask_valid_actions(network, deterministic):
    """Whole episodes with release actions: every action the policy takes is allowed by its mask, and releases (the
    release logits raised) are taken."""
    actor = release_actor(network, seed=1)
    with th.no_grad():
        actor.task_head[-1].bias[2] += 4.0
    layout = TaskAllocEnv(**RELEASE_ENV).observation_layout
    policy = LearnedPolicy(actor, layout.own_names, layout.task_names, OVERRIDES, deterministic=deterministic)
    kinds = {kind: 0 for kind in ActionKind}
    for seed in range(3):
        env = TaskAllocEnv(**RELEASE_ENV, max_cycles=60)
        obs, infos = env.reset(seed=seed)
        policy.start(env, seed)
        while env.agents:
            actions = policy.act(obs, infos)
            for agent, action in actions.items():
                assert obs[agent]["action_mask"][action] == 1, (seed, agent, action)
                kinds[decode(action, 8)[0]] += 1
            obs, _, _, _, infos = env.step(actions)
    assert kinds[ActionKind.RELEASE] > 0 and kinds[ActionKind.BID] > 0


def test_an_actor_refuses_a_mask_of_the_other_layout_in_one_line():
    """A release actor on a 1 + 2M mask, a plain one on a 1 + 3M mask, and each in a LearnedPolicy on the other
    environment: one clear line each."""
    obs, masks = observations(RELEASE_ENV, range(1), steps=1)
    with pytest.raises(ValueError, match=r"^the pooling actor has 3 actions per task \(bid, quit, release\): with 8 "
                                         r"tasks it takes a mask of 1 \+ 3·8 = 25 columns, got 17$"):
        masked_logits(release_actor("pooling"), obs, masks[:, :17])
    with pytest.raises(ValueError, match=r"^the attention actor has 2 actions per task \(bid, quit\).* got 25$"):
        masked_logits(AttentionActor(7, 22, 16, heads=2, layers=1), obs, masks)
    layout = TaskAllocEnv(**RELEASE_ENV).observation_layout
    policy = LearnedPolicy(release_actor("pooling"), layout.own_names, layout.task_names,
                           {"task_quitting": True, "delta": 1})         # what no checkpoint can say (see below)
    env = TaskAllocEnv("train_small", task_quitting=True, delta=1)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"1 \+ 3M layout .*; this environment has no release actions: build it with "
                                         "release_actions"):
        policy.start(env, 0)
    with pytest.raises(ValueError, match="kinds=4"):
        PoolingActor(7, 22, 16, kinds=4)


@pytest.mark.parametrize("network", ["pooling", "attention"])
def test_a_release_checkpoint_round_trips_and_carries_release_actions(tmp_path, network):
    """save → load: the same config (``kinds: 3``) and the same logits; ``learned:<path>`` builds the environment
    with release actions. A checkpoint whose kinds and ``release_actions`` disagree is refused, saving or loading."""
    actor = release_actor(network)
    layout = TaskAllocEnv(**RELEASE_ENV).observation_layout
    path = checkpoint.save(tmp_path / "model", actor, layout.own_names, layout.task_names, OVERRIDES)
    loaded = checkpoint.load(path)
    assert loaded.actor.config() == actor.config() and loaded.actor.config()["kinds"] == 3
    obs, masks = observations(RELEASE_ENV, range(2))
    np.testing.assert_array_equal(masked_logits(loaded.actor, obs, masks).numpy(),
                                  masked_logits(actor, obs, masks).numpy())
    policy = make_policy(f"learned:{path}")
    assert policy.env_overrides["release_actions"] is True
    env = TaskAllocEnv("train_small", **policy.env_overrides)
    env.reset(seed=0)
    policy.start(env, 0)
    with pytest.raises(CheckpointError, match="kinds=3 goes with release_actions true"):
        checkpoint.save(tmp_path / "bad", actor, layout.own_names, layout.task_names, {"task_quitting": True})
    spec = json.loads(path.read_text())
    spec["env_overrides"].pop("release_actions")
    (tmp_path / "model.json").write_text(json.dumps(spec))
    with pytest.raises(CheckpointError, match="kinds=3 goes with release_actions true"):
        checkpoint.load(tmp_path / "model.json")
    spec["network"]["config"]["kinds"] = 4
    (tmp_path / "model.json").write_text(json.dumps(spec))
    with pytest.raises(CheckpointError, match=r"cannot be built .*kinds=4"):
        checkpoint.load(tmp_path / "model.json")


def test_mappo_builds_the_release_actor_from_the_environment(tmp_path):
    """With ``release_actions`` in env_overrides the run's actor has release heads and its checkpoint the option;
    in a mixture entry's overrides the option is refused (the checkpoint would not carry it)."""
    mixture = "[{scenario: train_small, copies: 2}]"
    overrides = "{task_quitting: true, delta: 1, release_actions: true}"
    mappo.main(["--out-dir", str(tmp_path / "run"), "--mixture", mixture, "--env-overrides", overrides,
                "--actor", "pooling", "--hidden", "16", "--total-steps", "256", "--n-steps", "8",
                "--eval-episodes", "2", "--eval-freq", "0"])
    loaded = checkpoint.load(tmp_path / "run")
    assert loaded.actor.kinds == 3 and loaded.env_overrides["release_actions"] is True
    with pytest.raises(mappo.ConfigError, match="release_actions goes into env_overrides"):
        mappo.main(["--out-dir", str(tmp_path / "bad"), "--total-steps", "0",
                    "--mixture", "[{scenario: train_small, copies: 1, overrides: {release_actions: true}}]"])


def test_sb3_builds_the_release_actor_and_converts_it(tmp_path):
    """SB3's pooling body with ``kinds=3`` on an environment with release actions: masked logits of width 1 + 3M, and
    the checkpoint it writes loads with release heads."""
    pytest.importorskip("sb3_contrib")
    from sb3_contrib import MaskablePPO

    from taskalloc.training.sb3_policy import TaskMaskablePolicy, actor_of, save_checkpoint
    from taskalloc.training.vec_env import TaskAllocVecEnv, make_env_fns

    venv = TaskAllocVecEnv(make_env_fns(1, **RELEASE_ENV))
    model = MaskablePPO(TaskMaskablePolicy, venv, n_steps=16, batch_size=32, seed=0, device="cpu",
                        policy_kwargs={"body": "pooling", "hidden": 16, "kinds": 3})
    assert actor_of(model.policy).kinds == 3
    obs = venv.reset()
    with th.no_grad():
        dist = model.policy.get_distribution(model.policy.obs_to_tensor(obs)[0])
    assert dist.distribution.logits.shape == (venv.num_envs, 25)
    layout = TaskAllocEnv(**RELEASE_ENV).observation_layout
    path = save_checkpoint(tmp_path / "model", model.policy, layout, RELEASE_ENV, {})     # keeps the options only
    assert checkpoint.load(path).actor.kinds == 3
