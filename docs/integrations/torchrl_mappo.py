"""TorchRL MAPPO with masked actions on the batched env: a shared masked actor, a centralised critic, PPO's clipped
loss with GAE (TorchRL's multi-agent recipe, on TaskAllocTorchRLEnv)."""

import torch
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.collectors import Collector
from torchrl.data import LazyTensorStorage, ReplayBuffer, SamplerWithoutReplacement
from torchrl.modules import MaskedCategorical, MultiAgentMLP, ProbabilisticActor
from torchrl.objectives import ClipPPOLoss, ValueEstimators

from taskalloc_env.wrappers.torchrl import TaskAllocTorchRLEnv


def main(iterations: int = 2, instances: int = 16, steps: int = 32, seed: int = 0) -> dict[str, float]:
    torch.set_num_threads(1)
    torch.manual_seed(seed)
    env = TaskAllocTorchRLEnv(instances, scenario="train_small", reward_scale=100.0)   # as taskalloc train scales
    env.set_seed(seed)
    n, d = env.venv.n_agents, env.observation_spec["uav", "observation"].shape[-1]
    a = env.action_spec["uav", "action"].space.n
    logits = TensorDictModule(
        MultiAgentMLP(d, a, n, centralized=False, share_params=True, depth=2, num_cells=64),
        in_keys=[("uav", "observation")], out_keys=[("uav", "logits")])
    actor = ProbabilisticActor(logits, in_keys={"logits": ("uav", "logits"), "mask": ("uav", "action_mask")},
                               out_keys=[("uav", "action")], distribution_class=MaskedCategorical,
                               return_log_prob=True, log_prob_key=("uav", "sample_log_prob"))
    critic = TensorDictModule(                      # centralised: each agent's value sees every agent's observation
        MultiAgentMLP(d, 1, n, centralized=True, share_params=True, depth=2, num_cells=64),
        in_keys=[("uav", "observation")], out_keys=[("uav", "state_value")])
    loss = ClipPPOLoss(actor, critic, clip_epsilon=0.2, entropy_coeff=0.01, normalize_advantage=True,
                       normalize_advantage_exclude_dims=(-2,))      # per agent
    loss.set_keys(reward=("uav", "reward"), action=("uav", "action"), sample_log_prob=("uav", "sample_log_prob"),
                  value=("uav", "state_value"), done=("uav", "done"), terminated=("uav", "terminated"))
    loss.make_value_estimator(ValueEstimators.GAE, gamma=1.0, lmbda=0.95)
    optimiser = torch.optim.Adam(loss.parameters(), lr=3e-4)
    collector = Collector(env, actor, frames_per_batch=instances * steps, total_frames=iterations * instances * steps,
                          auto_register_policy_transforms=False)
    buffer = ReplayBuffer(storage=LazyTensorStorage(instances * steps), sampler=SamplerWithoutReplacement(),
                          batch_size=instances * steps // 4)
    scores = []                                     # (iteration, score) of every episode that ended
    for iteration, batch in enumerate(collector):
        with torch.no_grad():
            loss.value_estimator(batch, params=loss.critic_network_params,
                                 target_params=loss.target_critic_network_params)
        ended = batch["next", "done"].squeeze(-1)
        scores += [(iteration, s) for s in batch["next", "score"].squeeze(-1)[ended].tolist()]
        buffer.extend(batch.reshape(-1))
        for _ in range(4 * 4):                      # 4 epochs of 4 minibatches
            parts = loss(buffer.sample())
            total = parts["loss_objective"] + parts["loss_critic"] + parts["loss_entropy"]
            optimiser.zero_grad()
            total.backward()
            nn.utils.clip_grad_norm_(loss.parameters(), 0.5)
            optimiser.step()
        collector.update_policy_weights_()
    collector.shutdown()
    first = [s for i, s in scores if i < max(1, iterations // 5)]
    last = [s for i, s in scores if i >= iterations - max(1, iterations // 5)]
    return {"frames": iterations * instances * steps, "episodes": len(scores),
            "first fifth mean score": sum(first) / max(len(first), 1),
            "last fifth mean score": sum(last) / max(len(last), 1)}


if __name__ == "__main__":
    print(main())
