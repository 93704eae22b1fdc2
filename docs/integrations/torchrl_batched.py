"""TorchRL on the batched env: TaskAllocTorchRLEnv (an EnvBase of batch size [K]), spec check, masked rollouts."""

import torch
from torchrl.envs.utils import check_env_specs
from torchrl.modules import MaskedCategorical

from taskalloc_env.wrappers.torchrl import TaskAllocTorchRLEnv


def masked_random(td):
    mask = td["uav", "action_mask"]
    td["uav", "action"] = MaskedCategorical(logits=torch.zeros(mask.shape), mask=mask).sample()
    return td


def main(steps: int = 60) -> dict[str, tuple[int, ...]]:
    env = TaskAllocTorchRLEnv(8, scenario="train_small")       # 8 instances × 4 agents, reset through "_reset"
    env.set_seed(0)
    check_env_specs(env)
    rollout = env.rollout(steps, masked_random, break_when_any_done=False)
    return {"rollout": tuple(rollout.batch_size), "episodes": int(rollout["next", "done"].sum())}


if __name__ == "__main__":
    print(main())
