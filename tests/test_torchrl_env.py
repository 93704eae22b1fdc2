"""The TorchRL adapter of the batched env (``taskalloc_env.wrappers.torchrl``): TorchRL's spec check, rollouts across
partial resets, and the same instances as the batched env."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("torchrl")

from torchrl.envs.utils import check_env_specs  # noqa: E402
from torchrl.modules import MaskedCategorical  # noqa: E402

import taskalloc_env  # noqa: E402
from taskalloc_env.wrappers.torchrl import GROUP, TaskAllocTorchRLEnv  # noqa: E402


def masked_random(td):
    mask = td[GROUP, "action_mask"]
    td[GROUP, "action"] = MaskedCategorical(logits=torch.zeros(mask.shape), mask=mask).sample()
    return td


def test_specs_check():
    env = TaskAllocTorchRLEnv(3, scenario="train_small")
    env.set_seed(0)
    check_env_specs(env)


def test_rollout_across_resets_matches_the_batched_env():
    env = TaskAllocTorchRLEnv(3, scenario="train_small", max_cycles=30)
    env.set_seed(5)
    torch.manual_seed(0)
    rollout = env.rollout(90, masked_random, break_when_any_done=False)
    assert rollout.batch_size == torch.Size([3, 90])
    assert rollout["next", "done"].sum() >= 3                   # every instance ended at least once and restarted
    venv = taskalloc_env.vector_env(3, scenario="train_small", max_cycles=30, autoreset_mode="disabled")
    obs, _ = venv.reset(seed=5)
    assert np.array_equal(rollout[GROUP, "observation"][:, 0].numpy(), obs["observation"])
    for t in range(89):                      # replay the actions, restarting the instances that ended
        obs, rewards, term, trunc, _ = venv.step(rollout[GROUP, "action"][:, t].numpy())
        assert np.array_equal(rollout["next", GROUP, "reward"][:, t, :, 0].numpy(), rewards.astype(np.float32))
        assert np.array_equal(rollout["next", "terminated"][:, t, 0].numpy(), term)
        assert np.array_equal(rollout["next", "truncated"][:, t, 0].numpy(), trunc)
        if (term | trunc).any():
            obs, _ = venv.reset(options={"reset_mask": term | trunc})
        assert np.array_equal(rollout[GROUP, "observation"][:, t + 1].numpy(), obs["observation"])


def test_stepping_an_ended_instance_without_reset_is_refused():
    venv = taskalloc_env.vector_env(2, scenario="train_small", max_cycles=1, autoreset_mode="disabled")
    venv.reset(seed=0)
    venv.step(np.zeros((2, 4), dtype=np.int64))
    with pytest.raises(taskalloc_env.InvalidActionError, match="instance 0 ended: restart it with reset"):
        venv.step(np.zeros((2, 4), dtype=np.int64))
    with pytest.raises(taskalloc_env.ConfigError, match="reset_mask"):
        venv.reset(options={"reset_mask": [1, 0]})
