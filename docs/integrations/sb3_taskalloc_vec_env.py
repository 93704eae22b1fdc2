"""The project's own SB3 adapter: TaskAllocVecEnv (no SuperSuit) and MaskablePPO with the pooling network."""

import torch
from sb3_contrib import MaskablePPO

from taskalloc.training.sb3_policy import TaskMaskablePolicy
from taskalloc.training.vec_env import TaskAllocVecEnv, make_env_fns


def main(steps: int = 512) -> dict[str, int]:
    torch.set_num_threads(1)
    venv = TaskAllocVecEnv(make_env_fns(2, scenario="train_small"))      # 2 copies × 4 agents = 8 slots
    model = MaskablePPO(TaskMaskablePolicy, venv, n_steps=32, batch_size=64, n_epochs=2, seed=0, device="cpu",
                        policy_kwargs={"body": "pooling", "hidden": 64})
    model.learn(total_timesteps=steps)
    venv.close()
    return {"MaskablePPO": model.num_timesteps, "episodes": len(model.ep_info_buffer)}


if __name__ == "__main__":
    print(main())
