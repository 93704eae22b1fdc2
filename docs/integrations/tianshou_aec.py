"""Tianshou: the AEC view through its PettingZooEnv; masked random play, then independent DQN learners."""

import torch
from tianshou.algorithm import DQN, MARLRandomDiscreteMaskedOffPolicyAlgorithm, MultiAgentOffPolicyAlgorithm
from tianshou.algorithm.modelfree.dqn import DiscreteQLearningPolicy
from tianshou.algorithm.optim import AdamOptimizerFactory
from tianshou.data import Collector, CollectStats, VectorReplayBuffer
from tianshou.env import DummyVectorEnv
from tianshou.env.pettingzoo_env import PettingZooEnv
from tianshou.utils.net.common import Net

from taskalloc_env import taskalloc_v0


def get_env() -> PettingZooEnv:
    return PettingZooEnv(taskalloc_v0.env(scenario="train_small"))    # reads obs["action_mask"] as obs.mask


def main(episodes: int = 4, dqn_steps: int = 256) -> dict[str, float]:
    torch.set_num_threads(1)
    torch.manual_seed(0)
    env = get_env()
    random_team = MultiAgentOffPolicyAlgorithm(
        algorithms=[MARLRandomDiscreteMaskedOffPolicyAlgorithm(env.action_space) for _ in env.agents], env=env)
    stats = Collector[CollectStats](random_team, DummyVectorEnv([get_env] * 2), VectorReplayBuffer(2000, 2)).collect(
        n_episode=episodes, reset_before_collect=True)
    n_obs, n_act = env.observation_space["observation"].shape[0], int(env.action_space.n)
    learners = [DQN(policy=DiscreteQLearningPolicy(model=Net(state_shape=n_obs, action_shape=n_act,
                                                             hidden_sizes=[64, 64]),
                                                   action_space=env.action_space, eps_training=0.1),
                    optim=AdamOptimizerFactory(lr=1e-3), gamma=0.99, target_update_freq=100) for _ in env.agents]
    dqn_team = MultiAgentOffPolicyAlgorithm(algorithms=learners, env=env)
    collector = Collector[CollectStats](dqn_team, DummyVectorEnv([get_env] * 2), VectorReplayBuffer(5000, 2),
                                        exploration_noise=True)
    collector.reset()
    dqn = collector.collect(n_step=dqn_steps)
    return {"random episodes": stats.n_collected_episodes, "random team return": float(stats.returns.mean()),
            "dqn steps": dqn.n_collected_steps}


if __name__ == "__main__":
    print(main())
