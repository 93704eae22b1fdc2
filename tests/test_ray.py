"""Ray, when it is installed (``pip install taskalloc[ray]``): RLlib PPO trains, its checkpoint loads as a
``LearnedPolicy`` that takes the RLModule's greedy actions, and ``--backend ray`` writes the same tables as the local
backend for the same seeds. Each test starts a local Ray instance (``RAY_ADDRESS`` unset)."""

from __future__ import annotations

import numpy as np
import pytest
import torch as th

from taskalloc.evaluation import compare, experiment_files, experiments
from taskalloc.policies.learned import LearnedPolicy
from taskalloc.policies.networks import masked_logits
from taskalloc_env import TaskAllocEnv

ray = pytest.importorskip("ray")
pytest.importorskip("ray.rllib")
pytestmark = pytest.mark.slow


@pytest.fixture
def local_ray(monkeypatch):
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    yield
    ray.shutdown()


def test_rllib_ppo_trains_and_its_checkpoint_is_a_learned_policy(tmp_path, local_ray):
    from ray.rllib.core.columns import Columns
    from ray.rllib.core.rl_module.rl_module import RLModule

    from taskalloc.training import rllib_ppo

    summary = rllib_ppo.main(["train", "--out-dir", str(tmp_path), "--iterations", "2", "--train-batch", "128",
                              "--minibatch", "64", "--epochs", "1", "--network", "pooling", "--hidden", "32",
                              "--eval-episodes", "4"])
    assert summary["iterations"][-1]["agent_steps"] >= 2 * 128 * 4
    assert summary["validation"]["score"] > 0
    policy = LearnedPolicy.load(tmp_path)
    assert policy.env_overrides == {"task_quitting": True, "delta": 1} and policy.meta["algo"] == "rllib_ppo"
    # the RLlib module restored from its own checkpoint gives the logits the project checkpoint gives
    module = RLModule.from_checkpoint(str(tmp_path / "rllib" / "learner_group" / "learner" / "rl_module" / "shared"))
    env = TaskAllocEnv("train_small", **policy.env_overrides)
    obs, _ = env.reset(seed=10_000)
    x = np.stack([o["observation"] for o in obs.values()]).astype(np.float32)
    masks = np.stack([o["action_mask"] for o in obs.values()])
    with th.no_grad():
        out = module.forward_inference({Columns.OBS: {"observations": th.as_tensor(x),
                                                      "action_mask": th.as_tensor(masks, dtype=th.float32)}})
    np.testing.assert_array_equal(out[Columns.ACTION_DIST_INPUTS].numpy(), masked_logits(policy.actor, x, masks))
    # export: the RLlib checkpoint → the same project checkpoint
    written = rllib_ppo.main(["export", str(tmp_path / "rllib"), str(tmp_path / "exported")])
    exported = LearnedPolicy.load(written)
    for a, b in zip(exported.actor.state_dict().values(), policy.actor.state_dict().values()):
        assert th.equal(a, b)


def test_ray_backend_writes_the_local_backends_tables(tmp_path, local_ray):
    """compare and an experiment, local processes against Ray tasks: byte-identical tables and episode rows."""
    for backend in ("local", "ray"):
        compare.compare("train_small", 4, {}, jobs=2, out=tmp_path / backend, learned=["train_small"],
                        backend=backend)
        exp = experiment_files.load_experiment("fig5_16_l4")
        experiments.run_experiment(exp, tmp_path / backend / "exp", jobs=2, quick=True, progress=False,
                                   backend=backend)
    for name in ("compare.md", "compare.csv", "episodes.csv", "exp/fig5_16_l4/table.md",
                 "exp/fig5_16_l4/episodes.csv"):
        assert (tmp_path / "local" / name).read_bytes() == (tmp_path / "ray" / name).read_bytes(), name
    assert "learned (train_small)" in (tmp_path / "ray" / "compare.md").read_text()


@pytest.mark.parametrize("release", [False, True])
def test_the_rllib_module_has_release_logits_where_the_environment_has_release_actions(release):
    """The module's actor has the environment's kinds (3 with release actions), so its logits fill the action space."""
    import argparse

    from taskalloc.training import rllib_ppo

    overrides = {"task_quitting": True, "delta": 1, "release_actions": release}
    args = argparse.Namespace(scenario="train_small", set={}, env_overrides=overrides, max_cycles=200,
                              network="pooling", hidden=16, env_runners=0, envs_per_runner=1, train_batch=128,
                              minibatch=64, epochs=1, lr=3e-4, seed=0)
    ppo, config = rllib_ppo.build_config(args)
    env = rllib_ppo.make_env(config)
    agent = sorted(env.get_agent_ids())[0]
    spec = ppo.rl_module_spec.rl_module_specs[rllib_ppo.MODULE_ID]
    spec.observation_space, spec.action_space = env.observation_space[agent], env.action_space[agent]
    module = spec.build()
    assert module.actor.kinds == (3 if release else 2)
    assert module.actor.action_width(8) == spec.action_space.n == (25 if release else 17)
