"""TorchRL's PettingZooWrapper: spec check, batched masked-random rollouts, a masked MLP actor (float32 by default)."""

import torch
from tensordict.nn import TensorDictModule
from torchrl.envs import PettingZooWrapper, SerialEnv
from torchrl.envs.utils import check_env_specs
from torchrl.modules import MLP, MaskedCategorical, ProbabilisticActor

from taskalloc_env import taskalloc_v0


def make_env(seed: int = 0) -> PettingZooWrapper:
    # TorchRL fixes the info keys at the first reset: no episode record in the final infos (RewardSum counts returns)
    env = taskalloc_v0.parallel_env(scenario="train_small", episode_stats=False)
    return PettingZooWrapper(env, use_mask=True, return_state=True, categorical_actions=True, seed=seed)


def masked_random(td):
    mask = td["uav", "action_mask"]
    td["uav", "action"] = MaskedCategorical(logits=torch.zeros(mask.shape), mask=mask).sample()
    return td


def main(steps: int = 60) -> dict[str, tuple[int, ...]]:
    torch.set_num_threads(1)
    env = make_env()
    check_env_specs(env)
    batched = SerialEnv(2, make_env)
    random_rollout = batched.rollout(steps, policy=masked_random, break_when_any_done=False)
    batched.close()
    n_obs = env.observation_spec["uav", "observation", "observation"].shape[-1]
    n_act = env.full_action_spec["uav", "action"].space.n
    net = TensorDictModule(MLP(in_features=n_obs, out_features=n_act, num_cells=[64, 64]),
                           in_keys=[("uav", "observation", "observation")], out_keys=[("uav", "logits")])
    actor = ProbabilisticActor(net, in_keys={"logits": ("uav", "logits"), "mask": ("uav", "action_mask")},
                               out_keys=[("uav", "action")], distribution_class=MaskedCategorical)
    actor_rollout = env.rollout(steps, policy=actor)
    return {"random (2 envs)": tuple(random_rollout.batch_size), "mlp actor": tuple(actor_rollout.batch_size)}


if __name__ == "__main__":
    print(main())
