"""AgileRL: IPPO with one network for the agents' group (``uav``), masks read from infos (``MaskInInfos``).

AgileRL 2.58 pins pettingzoo<1.27, which the project allows (>=1.26); ``from agilerl.algorithms import IPPO`` also
needs ``peft`` (AgileRL imports it but installs it only with its llm extras).
"""

import numpy as np
import torch
from agilerl.algorithms import IPPO
from agilerl.training.train_multi_agent_on_policy import train_multi_agent_on_policy
from agilerl.utils.utils import make_multi_agent_vect_envs

from taskalloc_env import taskalloc_v0
from taskalloc_env.wrappers.agilerl import MaskInInfos


class MaskedIPPO(IPPO):
    """Works around an AgileRL 2.58 bug: ``IPPO.extract_action_masks`` tests ``None in group_masks``, which raises
    "The truth value of an array with more than one element is ambiguous" for any numpy mask (agilerl/algorithms/
    ippo.py:466); stack each group's ``(num_envs, n)`` masks the way its observations are stacked."""

    def extract_action_masks(self, infos):
        groups = {}
        for agent, info in infos.items():
            if isinstance(info, dict) and info.get("action_mask") is not None:
                group = self.get_group_id(agent) if self.has_grouped_agents() else agent
                groups.setdefault(group, []).append(np.atleast_2d(info["action_mask"]))
        return {g: torch.Tensor(np.concatenate(groups[g])) if g in groups else None for g in self.observation_space}


def make_env():
    return MaskInInfos(taskalloc_v0.parallel_env(scenario="train_small"))


def main(steps: int = 1024) -> dict[str, float]:
    torch.set_num_threads(1)
    env = make_multi_agent_vect_envs(make_env, num_envs=2)
    agents = env.possible_agents
    agent = MaskedIPPO(observation_spaces=[env.single_observation_space(a) for a in agents],
                       action_spaces=[env.single_action_space(a) for a in agents], agent_ids=agents,
                       net_config={"encoder_config": {"hidden_size": [64]}, "head_config": {"hidden_size": [64]}},
                       batch_size=64, learn_step=128, update_epochs=2, lr=3e-4, device="cpu")
    pop, fitnesses = train_multi_agent_on_policy(env, "taskalloc", "IPPO", [agent], max_steps=steps,
                                                 evo_steps=steps // 2, eval_loop=1, verbose=False)
    env.close()
    return {"steps": int(pop[0].steps), "fitness": float(fitnesses[0])}


if __name__ == "__main__":
    print(main())
