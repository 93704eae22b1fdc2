"""Ray RLlib (new API stack): PPO with the action-masking RLModule, one module shared by every agent.

A new local Ray instance by default; with ``RAY_ADDRESS`` set, ``ray.init`` joins that cluster (taskalloc must be
installed on its nodes; raise ``env_runners`` there to sample on them). ``"local"`` rather than Ray's own default
(None), which joins the last cluster started on this machine, and hung (over 10 min) when that one was gone.
"""

import os

import ray
import torch
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
from ray.rllib.core.rl_module.rl_module import RLModuleSpec
from ray.rllib.examples.rl_modules.classes.action_masking_rlm import ActionMaskingTorchRLModule
from ray.tune.registry import register_env

from taskalloc_env.wrappers.rllib import env_creator


def main(iterations: int = 2, env_runners: int = 0) -> dict[str, float]:
    torch.set_num_threads(1)
    ray.init(address=os.environ.get("RAY_ADDRESS", "local"), include_dashboard=False, log_to_driver=False)
    register_env("taskalloc", env_creator)                   # env_config: parallel_env's keywords or a suite task
    config = (
        PPOConfig()
        .environment("taskalloc", env_config={"task": "taskalloc/Small-v0"})
        .env_runners(num_env_runners=env_runners)                    # 0: sample in this process
        .learners(num_learners=0)
        .multi_agent(policies={"shared"}, policy_mapping_fn=lambda agent_id, *args, **kwargs: "shared")
        .rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs={"shared": RLModuleSpec(
            module_class=ActionMaskingTorchRLModule, model_config={"head_fcnet_hiddens": [64, 64]})}))
        .training(train_batch_size_per_learner=512, minibatch_size=128, num_epochs=2, lr=3e-4)
    )
    algo = config.build_algo()
    for _ in range(iterations):
        result = algo.train()
    algo.stop()
    ray.shutdown()
    runners = result["env_runners"]
    return {"iterations": result["training_iteration"], "env steps": runners["num_env_steps_sampled_lifetime"],
            "episode return": float(runners.get("episode_return_mean", float("nan")))}


if __name__ == "__main__":
    print(main())
