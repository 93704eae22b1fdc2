"""stable-baselines3 PPO and sb3-contrib MaskablePPO on SuperSuit's vector env: one policy shared by all agents."""

import torch
from sb3_contrib import MaskablePPO
from stable_baselines3 import PPO

from taskalloc_env import taskalloc_v0
from taskalloc_env.wrappers.sb3 import sb3_vec_env


def main(steps: int = 512) -> dict[str, int]:
    torch.set_num_threads(1)
    done = {}
    for algo in (PPO, MaskablePPO):
        venv = sb3_vec_env(taskalloc_v0.parallel_env(scenario="train_small"), copies=2)   # 2 copies × 4 agents
        model = algo("MultiInputPolicy", venv, n_steps=32, batch_size=64, n_epochs=2, seed=0, device="cpu")
        model.learn(total_timesteps=steps)
        done[algo.__name__] = model.num_timesteps
        venv.close()
    return done


if __name__ == "__main__":
    print(main())
