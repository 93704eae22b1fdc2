"""The SB3 adapter of the batched env (``training.batched_vec_env``): the same slots, rewards, dones and infos as
``TaskAllocVecEnv`` over env copies with the same seeds, and MaskablePPO trains on it."""

from __future__ import annotations

import numpy as np
import pytest

import taskalloc_env
from taskalloc.training.batched_vec_env import BatchedVecEnv
from taskalloc.training.vec_env import TaskAllocVecEnv, make_env_fns
from taskalloc_env.errors import ConfigError

KW = {"scenario": "train_small", "max_cycles": 40, "reward_scale": 100.0}


def pair(k: int = 3) -> tuple[BatchedVecEnv, TaskAllocVecEnv]:
    batched = BatchedVecEnv(taskalloc_env.vector_env(k, autoreset_mode="same_step", **KW))
    copies = TaskAllocVecEnv(make_env_fns(k, **KW))
    return batched, copies


def test_slots_match_the_copies_adapter_step_by_step():
    batched, copies = pair()
    for venv in (batched, copies):
        venv.seed(4)
    obs_b, obs_c = batched.reset(), copies.reset()
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(150):
        for key in ("observation", "action_mask"):
            assert np.array_equal(obs_b[key], obs_c[key])
        masks = batched.action_masks()
        assert np.array_equal(masks, copies.action_masks())
        assert np.array_equal(np.stack(batched.env_method("action_masks")), masks)
        actions = (rng.random(masks.shape) * masks).argmax(axis=1)
        obs_b, r_b, d_b, i_b = batched.step(actions)
        obs_c, r_c, d_c, i_c = copies.step(actions)
        assert np.array_equal(r_b, r_c) and np.array_equal(d_b, d_c)
        for slot in np.flatnonzero(d_b):
            ends += 1
            assert i_b[slot]["TimeLimit.truncated"] == i_c[slot]["TimeLimit.truncated"]
            for key in ("observation", "action_mask"):
                assert np.array_equal(i_b[slot]["terminal_observation"][key], i_c[slot]["terminal_observation"][key])
            if "episode" in i_c[slot]:
                mine, theirs = dict(i_b[slot]["episode"]), dict(i_c[slot]["episode"])
                assert mine.pop("r") == pytest.approx(theirs.pop("r"))
                mine.pop("t"), theirs.pop("t")
                assert mine == theirs
            else:
                assert "episode" not in i_b[slot]
    assert ends > 0


def test_needs_same_step_autoreset():
    with pytest.raises(ConfigError, match="same_step"):
        BatchedVecEnv(taskalloc_env.vector_env(2, scenario="train_small"))


def test_maskable_ppo_trains_on_it():
    from sb3_contrib import MaskablePPO

    venv = BatchedVecEnv(taskalloc_env.vector_env(4, autoreset_mode="same_step", **KW))
    model = MaskablePPO("MultiInputPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=2 * 32 * venv.num_envs)
    assert model.num_timesteps == 2 * 32 * venv.num_envs
    assert len(model.ep_info_buffer) > 0
