"""MAPPO (``taskalloc.training.mappo``): the critic sees ``env.state()`` and the actor does not, rollouts store each
step, checkpoints reproduce actions exactly, the attention actor is a set function of the tasks, and a short run
learns."""

from __future__ import annotations

import csv
import dataclasses

import numpy as np
import pytest
import torch as th

from taskalloc.evaluation.seeds import VALIDATION_SEED_START
from taskalloc.policies import make_policy, rollout
from taskalloc.policies.learned import LearnedPolicy
from taskalloc.policies.networks import MASKED_LOGIT, AttentionActor, masked_logits
from taskalloc.training import mappo
from taskalloc.training.critic import StateCritic, state_tokens
from taskalloc_env import ConfigError, TaskAllocEnv

ENV = {"scenario": "train_small", "task_quitting": True, "delta": 1}


def small_config(**fields) -> mappo.MappoConfig:
    cfg = mappo.MappoConfig(hidden=32, heads=2, layers=1, **fields)
    cfg.check()
    return cfg


def model_for(group: mappo.Group, cfg: mappo.MappoConfig, seed: int = 0) -> mappo.ActorCritic:
    th.manual_seed(seed)
    actor = mappo.make_actor(cfg, group.layout.own_size, group.layout.task_size)
    model = mappo.ActorCritic(actor, StateCritic(group.n_equipment, cfg.hidden, cfg.heads))
    with th.no_grad():          # output layers away from zero, so that logits differ clearly between actions
        for layer in actor.output_layers():
            layer.weight.normal_(0, 1.0)
    return model


def test_the_critic_sees_the_state_and_the_actor_does_not():
    """Moving agent 1 changes the global state (and the critic's value) but not agent 0's observation (nor its
    logits): the actor acts from the local observation only, the critic from ``env.state()`` only."""
    env = TaskAllocEnv(**ENV)
    obs, _ = env.reset(seed=3)
    scenario = env.unwrapped.scenario
    positions = scenario.agent_pos.copy()
    positions[1, :2] = scenario.arena[0] - positions[1, :2]
    moved = dataclasses.replace(scenario, agent_pos=positions)
    other = TaskAllocEnv(scenario=moved, task_quitting=True, delta=1)
    obs_moved, _ = other.reset(seed=3)
    np.testing.assert_array_equal(obs["uav_0"]["observation"], obs_moved["uav_0"]["observation"])
    assert not np.array_equal(env.state(), other.state())
    cfg = small_config()
    group = mappo.Group({"scenario": "train_small"}, cfg.env_overrides, cfg.max_cycles, 0)
    model = model_for(group, cfg)
    logits = [masked_logits(model.actor, o["uav_0"]["observation"][None], o["uav_0"]["action_mask"][None])
              for o in (obs, obs_moved)]
    np.testing.assert_array_equal(logits[0].numpy(), logits[1].numpy())
    with th.no_grad():
        values = [float(model.value(th.as_tensor(e.state()[None], dtype=th.float32), 4, 8)) for e in (env, other)]
    assert values[0] != values[1]
    # the critic's input is the state alone: the tokens carry the positions of every agent and task
    agents, tasks = state_tokens(th.as_tensor(other.state()[None], dtype=th.float32), 4, 8, 0)
    np.testing.assert_allclose(agents[0, :, :3].numpy(), moved.agent_pos / np.asarray(moved.arena), atol=1e-6)
    np.testing.assert_allclose(tasks[0, :, :3].numpy(), moved.task_pos / np.asarray(moved.arena), atol=1e-6)
    with pytest.raises(ValueError, match="does not fit"):
        state_tokens(th.zeros(1, 50), 4, 8, 0)


def test_a_rollout_stores_every_step_and_its_returns_add_up():
    """Each stored state, observation and mask is the one the step acted on (the group's arrays are reused in
    place), and with λ = γ = 1 the return at the first step is the whole episode's reward: its final score / (c̄·N)."""
    cfg = small_config()
    group = mappo.Group({"scenario": "train_small", "copies": 1}, cfg.env_overrides, cfg.max_cycles, 0)
    group.reset()
    first_state, first_obs = group.states.copy(), group.obs.copy()
    model = model_for(group, cfg)
    r = mappo.collect(model, group, n_steps=40, gamma=1.0, gae_lambda=1.0)
    assert r.states.shape == (40, len(first_state[0])) and r.obs.shape[0] == 40 * 4
    np.testing.assert_array_equal(r.states[:1].numpy(), first_state.astype(np.float32))
    np.testing.assert_array_equal(r.obs[:4].numpy(), first_obs.reshape(4, -1).astype(np.float32))
    assert len({tuple(s) for s in r.states.numpy()}) > 20
    assert (r.masks[~r.decisions].sum(dim=1) == 1).all() and r.decisions.any()
    # every agent of a copy shares the copy's advantage
    np.testing.assert_allclose(r.agent_adv.reshape(-1, 4).numpy(),
                               np.repeat((r.returns - r.values).numpy()[:, None], 4, 1), atol=1e-6)
    assert group.scores, "an episode of train_small ends within 40 steps"
    assert float(r.returns[0]) == pytest.approx(group.scores[0] / group.reward_scale, abs=1e-4)


def test_checkpoint_round_trip_reproduces_actions_exactly(tmp_path):
    cfg = small_config()
    group = mappo.Group({"scenario": "train_small"}, cfg.env_overrides, cfg.max_cycles, 0)
    model = model_for(group, cfg)
    path = mappo.save_actor(tmp_path / "model", model.actor, group, cfg, {"note": "test"})
    loaded = LearnedPolicy.load(path)
    assert loaded.meta == {"note": "test"} and loaded.env_overrides == {"task_quitting": True, "delta": 1}
    assert isinstance(loaded.actor, AttentionActor)
    original = mappo.as_learned(model.actor, group, cfg)
    model.actor.eval()
    env = TaskAllocEnv("train_small", invalid_action="raise", **loaded.env_overrides)
    for seed in range(10_000, 10_003):
        obs, infos = env.reset(seed=seed)
        loaded.start(env, seed)
        original.start(env, seed)
        while env.agents:
            stacked = np.stack([o["observation"] for o in obs.values()])
            masks = np.stack([o["action_mask"] for o in obs.values()])
            np.testing.assert_array_equal(masked_logits(loaded.actor, stacked, masks).numpy(),
                                          masked_logits(model.actor, stacked, masks).numpy())
            actions = loaded.act(obs, infos)
            assert actions == original.act(obs, infos)
            obs, _, _, _, infos = env.step(actions)
    # no weight depends on the number of agents or tasks: it plays a larger scenario to convergence
    big = TaskAllocEnv("train_small", n_agents=6, n_tasks=12, invalid_action="raise", **loaded.env_overrides)
    assert rollout(big, loaded, seed=1).converged


def test_attention_actor_is_task_permutation_equivariant_and_masks():
    th.manual_seed(0)
    actor = AttentionActor(7, 22, hidden=32, heads=2, layers=2).eval()
    env = TaskAllocEnv(**ENV)
    obs, infos = env.reset(seed=5)
    cbga = make_policy("cbga")
    cbga.start(env)
    obs, *_ = env.step(cbga.act(obs, infos))
    x = np.stack([o["observation"] for o in obs.values()])
    masks = np.stack([o["action_mask"] for o in obs.values()])
    own, tasks = env.observation_layout.split(x)
    perm = np.random.default_rng(0).permutation(8)
    x_p = np.concatenate([own, tasks[:, perm].reshape(len(x), -1)], axis=1)
    masks_p = np.concatenate([masks[:, :1], masks[:, 1:9][:, perm], masks[:, 9:][:, perm]], axis=1)
    base = masked_logits(actor, x, masks).numpy()
    permuted = masked_logits(actor, x_p, masks_p).numpy()
    np.testing.assert_allclose(permuted[:, 0], base[:, 0], atol=1e-5)
    np.testing.assert_allclose(permuted[:, 1:9], base[:, 1:9][:, perm], atol=1e-5)
    np.testing.assert_allclose(permuted[:, 9:], base[:, 9:][:, perm], atol=1e-5)
    assert (base[masks == 0] == MASKED_LOGIT).all() and (base[masks == 1] > MASKED_LOGIT / 2).all()


def test_bad_configs_are_refused_in_one_line(capsys):
    with pytest.raises(ConfigError, match="not options a policy plays by"):
        mappo.load_config(["--env-overrides", "{n_agents: 3}"])
    with pytest.raises(ConfigError, match="overlap the test seeds"):
        mappo.load_config(["--seed", "10"])
    with pytest.raises(ConfigError, match="must be a mapping with 'scenario'"):
        mappo.load_config(["--mixture", "[{scenario: train_small, size: 3}]"])
    with pytest.raises(ConfigError, match="'actor': got 'mlp'"):
        mappo.load_config(["--actor", "mlp"])
    from taskalloc_env.errors import run_cli
    assert run_cli(lambda: mappo.main(["--hidden", "30", "--heads", "4"])) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_a_mixture_needs_one_feature_set(tmp_path):
    mixture = "[{scenario: train_small}, {scenario: train_small, overrides: {message_loss: 0.2}}]"
    with pytest.raises(ConfigError, match="other observation features"):
        mappo.main(["--out-dir", str(tmp_path), "--mixture", mixture, "--total-steps", "0"])


# A variant of train_small where the choice of task matters more (3 agents, start times within 10 min): uniform
# random play reaches about 90 % of CBGABI here (321 against 356 on the 24 validation seeds), against 94 % on
# train_small (as in test_training_smoke).
HARD = {"n_agents": 3, "start_time_range": [0.0, 10.0]}


@pytest.mark.slow
def test_a_short_run_improves_on_its_starting_policy(tmp_path):
    mixture = f"[{{scenario: train_small, copies: 8, overrides: {HARD}}}]"
    summary = mappo.main(["--out-dir", str(tmp_path), "--mixture", mixture, "--total-steps", "24000",
                          "--n-steps", "32", "--n-epochs", "8", "--hidden", "32", "--heads", "2", "--layers", "1",
                          "--learning-rate", "1e-3", "--ent-coef", "0", "--eval-freq", "0", "--eval-episodes", "24"])
    with open(tmp_path / "eval.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    first, last = (float(rows[i]["score"]) for i in (0, -1))
    seeds = range(VALIDATION_SEED_START, VALIDATION_SEED_START + 24)
    env = TaskAllocEnv("train_small", task_quitting=True, delta=1, **HARD)
    random_score = np.mean([rollout(env, make_policy("random"), seed=s).score for s in seeds])
    assert int(rows[-1]["steps"]) == summary["steps"] >= 24000
    # measured with --seed 0…4 (numpy 2.4, torch 2.13): 240–340 at the start, 338–359 after 24 576 steps; random
    # play 321, CBGABI 356. After 12 288 steps one seed was still below random play (318), hence the longer run.
    assert last > first and last > random_score and last > 0.9 * float(rows[-1]["baseline_score"])
    # the saved model is what the last evaluation measured
    policy = LearnedPolicy.load(tmp_path)
    assert np.mean([rollout(env, policy, seed=s).score for s in seeds]) == pytest.approx(last)
    assert summary["parameters"]["critic"] > 0 and summary["agent_steps_per_second"] > 0


def test_a_group_on_the_batched_env_plays_the_episodes_of_separate_copies():
    """Without a partner a group steps one batched env; the same seeds and actions give the same observations,
    rewards, episode ends, cut states and scores as stepping separate env copies (the path a partner needs)."""
    cfg = mappo.MappoConfig()
    entry = {"scenario": "train_small", "copies": 3}
    batched = mappo.Group(entry, cfg.env_overrides, 12, 0)
    separate = mappo.Group(entry, cfg.env_overrides, 12, 0)
    separate.batch = None                         # the per-copy path, as with a partner that plays no round
    separate.envs = [TaskAllocEnv(**separate.env_kwargs, max_cycles=12, reward_scale=separate.reward_scale)
                     for _ in range(3)]
    separate.partner = None
    batched.reset(), separate.reset()
    rng = np.random.default_rng(0)
    for _ in range(40):
        for name in ("obs", "masks", "states"):
            assert np.array_equal(getattr(batched, name), getattr(separate, name)), name
        actions = (rng.random(batched.masks.shape) * batched.masks).argmax(axis=2)
        r_b, d_b, c_b = batched.step(actions)
        r_s, d_s, c_s = separate.step(actions)
        assert np.array_equal(r_b, r_s) and np.array_equal(d_b, d_s)
        assert all((a is None and b is None) or np.array_equal(a, b) for a, b in zip(c_b, c_s))
    assert batched.scores == separate.scores and len(batched.scores) >= 3
