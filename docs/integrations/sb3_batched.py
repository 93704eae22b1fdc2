"""stable-baselines3 on the batched env: BatchedVecEnv over vector_env, MaskablePPO with the pooling network."""

import torch
from sb3_contrib import MaskablePPO

import taskalloc_env
from taskalloc.training.batched_vec_env import BatchedVecEnv
from taskalloc.training.sb3_policy import TaskMaskablePolicy


def main(steps: int = 512) -> dict[str, int]:
    torch.set_num_threads(1)
    venv = BatchedVecEnv(taskalloc_env.vector_env(4, scenario="train_small", autoreset_mode="same_step"))
    model = MaskablePPO(TaskMaskablePolicy, venv, n_steps=32, batch_size=64, n_epochs=2, seed=0, device="cpu",
                        policy_kwargs={"body": "pooling", "hidden": 64})     # 4 instances × 4 agents = 16 slots
    model.learn(total_timesteps=steps)
    venv.close()
    return {"MaskablePPO": model.num_timesteps, "episodes": len(model.ep_info_buffer)}


if __name__ == "__main__":
    print(main())
