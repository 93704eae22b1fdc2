"""The policy network, LearnedPolicy (save/load round trip), behaviour cloning and mixed teams."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("sb3_contrib")

import torch as th
from sb3_contrib import MaskablePPO

from policies import make_policy, rollout
from policies.learned import LearnedPolicy
from taskalloc_env import TaskAllocEnv
from training.bc import behaviour_cloning, collect_demonstrations
from training.network import MASKED_LOGIT, TaskMaskablePolicy, masked_logits
from training.teams import MixedTeamPolicy
from training.vec_env import TaskAllocVecEnv, make_env_fns

ENV = {"scenario": "train_small", "task_quitting": True, "delta": 1, "reward_scale": 100.0}


def make_model(body: str = "pooling", seed: int = 0) -> MaskablePPO:
    venv = TaskAllocVecEnv(make_env_fns(1, **ENV))
    model = MaskablePPO(TaskMaskablePolicy, venv, n_steps=16, batch_size=32, seed=seed, device="cpu",
                        policy_kwargs={"body": body, "hidden": 32 if body == "pooling" else 64})
    model.taskalloc = {"env_overrides": dict(ENV), "scenario": "train_small"}
    return model


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
        for layer in model.policy.mlp_extractor.output_layers():
            layer.weight.normal_(0, 1.0)
    return model


def test_logits_are_masked(perturbed_model):
    obs, masks = sample_observations()
    logits = masked_logits(perturbed_model.policy, obs, masks).numpy()
    assert logits.shape == masks.shape
    assert (logits[masks == 0] == MASKED_LOGIT).all()
    assert (logits[masks == 1] > MASKED_LOGIT / 2).all()


def test_pooling_network_is_task_permutation_equivariant_and_size_agnostic(perturbed_model):
    policy = perturbed_model.policy
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
    path = tmp_path / "model.zip"
    perturbed_model.save(path)
    loaded = LearnedPolicy.load(path)
    via_registry = make_policy(f"learned:{path}")
    from_dir = LearnedPolicy.load(tmp_path)
    obs, masks = sample_observations(seed=3)
    expected = masked_logits(perturbed_model.policy, obs, masks).numpy()
    for policy in (loaded, via_registry, from_dir):
        np.testing.assert_array_equal(masked_logits(policy.policy, obs, masks).numpy(), expected)
    assert loaded.env_overrides == {"task_quitting": True, "delta": 1}
    # the loaded policy plays whole episodes with invalid_action="raise", reproducibly, like the original
    env = TaskAllocEnv("train_small", **loaded.env_overrides)
    original = LearnedPolicy(perturbed_model.policy, perturbed_model.taskalloc)
    scores = [rollout(env, p, seed=10_000 + k).score for p in (loaded, original) for k in range(3)]
    assert scores[:3] == scores[3:]
    # a pooling checkpoint also plays a scenario with more agents and tasks
    big = TaskAllocEnv("train_small", n_agents=6, n_tasks=12, **loaded.env_overrides)
    assert rollout(big, loaded, seed=1).score >= 0.0
    with pytest.raises(FileNotFoundError):
        LearnedPolicy.load(tmp_path / "missing.zip")


def test_mlp_checkpoint_refuses_another_number_of_tasks(tmp_path):
    model = make_model(body="mlp")
    model.save(tmp_path / "mlp.zip")
    policy = LearnedPolicy.load(tmp_path / "mlp.zip")
    assert rollout(TaskAllocEnv("train_small", **policy.env_overrides), policy, seed=0).score >= 0.0
    env = TaskAllocEnv("train_small", n_tasks=10, **policy.env_overrides)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="tied to the number of tasks"):
        policy.start(env, 0)


def test_behaviour_cloning_reproduces_the_expert():
    expert = make_policy("cbgabi")
    train = collect_demonstrations(ENV, n_episodes=60, seed_start=100_000)
    held_out = collect_demonstrations(ENV, n_episodes=20, seed_start=200_000)
    assert len(train) > 60 * 4 * 5 and train.action_mask[np.arange(len(train)), train.action].all()
    model = make_model(seed=1)
    logits = masked_logits(model.policy, held_out.observation, held_out.action_mask)
    before = float((logits.argmax(1).numpy() == held_out.action).mean())
    history = behaviour_cloning(model.policy, train, epochs=8, learning_rate=3e-3)
    logits = masked_logits(model.policy, held_out.observation, held_out.action_mask)
    after = float((logits.argmax(1).numpy() == held_out.action).mean())
    assert history[-1]["nll"] < history[0]["nll"]
    assert after > 0.9 > before
    # the cloned policy's team score is close to the expert's on fresh instances
    env = TaskAllocEnv("train_small", **expert.env_overrides)
    cloned = LearnedPolicy(model.policy, model.taskalloc)
    seeds = range(10_000, 10_010)
    clone_score = np.mean([rollout(env, cloned, seed=s).score for s in seeds])
    expert_score = np.mean([rollout(env, expert, seed=s).score for s in seeds])
    assert clone_score > 0.95 * expert_score


def test_mixed_team_lets_scripted_agents_play_their_own_policy(perturbed_model):
    learned = LearnedPolicy(perturbed_model.policy, perturbed_model.taskalloc)
    team = MixedTeamPolicy(learned, {"uav_0": "cbga", "uav_3": "cbgabi"})
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
        learned_part = learned.act({a: obs[a] for a in ("uav_1", "uav_2")})
        assert {a: actions[a] for a in ("uav_1", "uav_2")} == learned_part
        obs, _, _, _, infos = env.step(actions)
        steps += 1
    assert steps > 1
