"""The policy network, LearnedPolicy (checkpoint round trip), behaviour cloning and mixed teams."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("sb3_contrib")

import torch as th
from helpers import assert_same_actions
from sb3_contrib import MaskablePPO

from taskalloc.policies import make_policy, rollout
from taskalloc.policies.learned import LearnedPolicy
from taskalloc.policies.networks import MASKED_LOGIT, masked_logits
from taskalloc.policies.teams import MixedTeamPolicy
from taskalloc.training.bc import behaviour_cloning, collect_demonstrations
from taskalloc.training.sb3_policy import TaskMaskablePolicy, actor_of, as_learned, save_checkpoint
from taskalloc.training.vec_env import TaskAllocVecEnv, make_env_fns
from taskalloc_env import TaskAllocEnv

pytestmark = pytest.mark.slow

ENV = {"scenario": "train_small", "task_quitting": True, "delta": 1, "reward_scale": 100.0}


def make_model(body: str = "pooling", seed: int = 0) -> MaskablePPO:
    venv = TaskAllocVecEnv(make_env_fns(1, **ENV))
    model = MaskablePPO(TaskMaskablePolicy, venv, n_steps=16, batch_size=32, seed=seed, device="cpu",
                        policy_kwargs={"body": body, "hidden": 32 if body == "pooling" else 64})
    return model


LAYOUT = TaskAllocEnv(**ENV).observation_layout


def learned(model: MaskablePPO) -> LearnedPolicy:
    return as_learned(model.policy, LAYOUT, ENV)


def sample_observations(n_tasks: int = 8, seed: int = 0, steps: int = 3) -> tuple[np.ndarray, np.ndarray]:
    env = TaskAllocEnv(**{**ENV, "n_tasks": n_tasks})
    obs, infos = env.reset(seed=seed)
    cbga = make_policy("cbga")
    cbga.start(env)
    rows, masks = [], []
    for _ in range(steps):
        rows += [o["observation"] for o in obs.values()]
        masks += [o["action_mask"] for o in obs.values()]
        obs, _, _, _, infos = env.step(cbga.act(obs, infos))
    return np.stack(rows), np.stack(masks)


@pytest.fixture(scope="module")
def perturbed_model() -> MaskablePPO:
    """A model whose output layers are not near zero, so that logits differ clearly between actions."""
    model = make_model()
    th.manual_seed(0)
    with th.no_grad():
        for layer in actor_of(model.policy).output_layers():
            layer.weight.normal_(0, 1.0)
    return model


def test_logits_are_masked(perturbed_model):
    obs, masks = sample_observations()
    logits = masked_logits(actor_of(perturbed_model.policy), obs, masks).numpy()
    assert logits.shape == masks.shape
    assert (logits[masks == 0] == MASKED_LOGIT).all()
    assert (logits[masks == 1] > MASKED_LOGIT / 2).all()


def test_pooling_network_is_task_permutation_equivariant_and_size_agnostic(perturbed_model):
    policy = actor_of(perturbed_model.policy)
    obs, masks = sample_observations()
    layout = TaskAllocEnv(**ENV).observation_layout
    own, tasks = layout.split(obs)
    perm = np.random.default_rng(0).permutation(8)
    obs_p = np.concatenate([own, tasks[:, perm].reshape(len(obs), -1)], axis=1)
    masks_p = np.concatenate([masks[:, :1], masks[:, 1:9][:, perm], masks[:, 9:][:, perm]], axis=1)
    base = masked_logits(policy, obs, masks).numpy()
    permuted = masked_logits(policy, obs_p, masks_p).numpy()
    np.testing.assert_allclose(permuted[:, 0], base[:, 0], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(permuted[:, 1:9], base[:, 1:9][:, perm], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(permuted[:, 9:], base[:, 9:][:, perm], rtol=1e-5, atol=1e-5)
    obs12, masks12 = sample_observations(n_tasks=12)
    assert masked_logits(policy, obs12, masks12).shape == (len(obs12), 25)


def test_save_load_round_trip(tmp_path, perturbed_model):
    """A checkpoint reproduces the saved actions exactly, through every way of naming it."""
    json_path = save_checkpoint(tmp_path / "model", perturbed_model.policy, LAYOUT, ENV, {"note": "test"})
    loaded = LearnedPolicy.load(json_path)
    via_registry = make_policy(f"learned:{tmp_path / 'model'}")
    from_dir = LearnedPolicy.load(tmp_path)
    obs, masks = sample_observations(seed=3)
    expected = masked_logits(actor_of(perturbed_model.policy), obs, masks).numpy()
    for policy in (loaded, via_registry, from_dir):
        np.testing.assert_array_equal(masked_logits(policy.actor, obs, masks).numpy(), expected)
    assert loaded.env_overrides == {"task_quitting": True, "delta": 1}
    assert loaded.meta == {"note": "test"}
    # the loaded policy takes the original's actions, step by step, over whole episodes (invalid_action="raise")
    env = TaskAllocEnv("train_small", invalid_action="raise", **loaded.env_overrides)
    assert_same_actions(env, loaded, learned(perturbed_model), range(10_000, 10_003))
    # a pooling checkpoint also plays a scenario with more agents and tasks, to convergence, within its masks
    big = TaskAllocEnv("train_small", n_agents=6, n_tasks=12, invalid_action="raise", **loaded.env_overrides)
    assert rollout(big, loaded, seed=1).converged
    with pytest.raises(ValueError, match="no checkpoint"):
        LearnedPolicy.load(tmp_path / "missing.json")


def test_mlp_checkpoint_refuses_another_number_of_tasks(tmp_path):
    model = make_model(body="mlp")
    save_checkpoint(tmp_path / "mlp", model.policy, LAYOUT, ENV, {})
    policy = LearnedPolicy.load(tmp_path / "mlp.json")
    obs, masks = sample_observations(seed=2)
    np.testing.assert_array_equal(masked_logits(policy.actor, obs, masks).numpy(),
                                  masked_logits(actor_of(model.policy), obs, masks).numpy())
    env = TaskAllocEnv("train_small", n_tasks=10, **policy.env_overrides)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="tied to the number of tasks"):
        policy.start(env, 0)


def test_committed_models_load_by_name_and_beat_random():
    """The committed checkpoints load by name (no unpickling) and score clearly above uniform random play on held-out
    instances where the choice matters (start times within 10 min; measured: random 390, the SB3 models 461–465,
    CBGABI 450 on these seeds; on train_small itself random play already reaches 97 % of CBGABI)."""
    seeds = range(10_000, 10_030)
    random_policy = make_policy("random")
    env = TaskAllocEnv("train_small", start_time_range=[0.0, 10.0], **make_policy("cbgabi").env_overrides)
    random_score = np.mean([rollout(env, random_policy, seed=s).score for s in seeds])
    for name in ("train_small", "mappo_small_pooling_1m"):
        policy = make_policy(f"learned:{name}")
        assert policy.env_overrides == {"task_quitting": True, "delta": 1}
        score = np.mean([rollout(env, policy, seed=s).score for s in seeds])
        assert score > 1.1 * random_score, f"{name}: {score:.1f} vs random {random_score:.1f}"


def test_the_committed_mappo_model_loads_by_name_and_plays():
    """``learned:mappo_small`` loads by name with its protocol options and plays held-out instances of its training
    scenario. No score bound: on the start-time variant above it scores far below random play (108 against 415 on
    these seeds; docs/learning.md, all-pass first rounds), which is a finding about the model, not about loading."""
    policy = make_policy("learned:mappo_small")
    assert policy.env_overrides == {"task_quitting": True, "delta": 1}
    env = TaskAllocEnv("train_small", **policy.env_overrides)
    scores = [rollout(env, policy, seed=s).score for s in range(10_000, 10_005)]
    assert all(np.isfinite(scores)) and max(scores) > 0


def test_behaviour_cloning_reproduces_the_expert():
    expert = make_policy("cbgabi")
    train = collect_demonstrations(ENV, n_episodes=60, seed_start=100_000)
    held_out = collect_demonstrations(ENV, n_episodes=20, seed_start=200_000)
    assert len(train) > 60 * 4 * 5 and train.action_mask[np.arange(len(train)), train.action].all()
    model = make_model(seed=1)
    logits = masked_logits(actor_of(model.policy), held_out.observation, held_out.action_mask)
    before = float((logits.argmax(1).numpy() == held_out.action).mean())
    history = behaviour_cloning(model.policy, train, epochs=8, learning_rate=3e-3)
    logits = masked_logits(actor_of(model.policy), held_out.observation, held_out.action_mask)
    after = float((logits.argmax(1).numpy() == held_out.action).mean())
    assert history[-1]["nll"] < history[0]["nll"]
    assert after > 0.9 > before
    # the cloned policy's team score is close to the expert's on fresh instances
    env = TaskAllocEnv("train_small", **expert.env_overrides)
    cloned = learned(model)
    seeds = range(10_000, 10_010)
    clone_score = np.mean([rollout(env, cloned, seed=s).score for s in seeds])
    expert_score = np.mean([rollout(env, expert, seed=s).score for s in seeds])
    assert clone_score > 0.95 * expert_score


def test_mixed_team_lets_scripted_agents_play_their_own_policy(perturbed_model):
    learned_policy = learned(perturbed_model)
    team = MixedTeamPolicy(learned_policy, {"uav_0": "cbga", "uav_3": "cbgabi"})
    assert team.env_overrides == {"task_quitting": True, "delta": 1}
    env = TaskAllocEnv("train_small", **team.env_overrides)
    cbga, cbgabi = make_policy("cbga"), make_policy("cbgabi")
    obs, infos = env.reset(seed=4)
    team.start(env, 4)
    cbga.start(env, 4)
    cbgabi.start(env, 4)
    steps = 0
    while env.agents:
        actions = team.act(obs, infos)
        assert set(actions) == set(obs)
        assert actions["uav_0"] == cbga.act({"uav_0": obs["uav_0"]})["uav_0"]
        assert actions["uav_3"] == cbgabi.act({"uav_3": obs["uav_3"]})["uav_3"]
        learned_part = learned_policy.act({a: obs[a] for a in ("uav_1", "uav_2")})
        assert {a: actions[a] for a in ("uav_1", "uav_2")} == learned_part
        obs, _, _, _, infos = env.step(actions)
        steps += 1
    assert steps > 1
