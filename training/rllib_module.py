"""The RLlib RLModule of ``taskalloc.training.rllib_ppo``, in a module of its own so that its class pickles by an
importable name (RLlib pickles the module class into checkpoints and ships it to remote EnvRunners; a class defined in
``__main__`` would not load there).
"""

from __future__ import annotations

from typing import Any

import torch as th
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.apis import ValueFunctionAPI
from ray.rllib.core.rl_module.torch import TorchRLModule
from torch import nn

from taskalloc.policies.networks import AttentionActor, PoolingActor, PoolingEncoder, split_tasks

NETWORKS = {"attention": AttentionActor, "pooling": PoolingActor}


class TaskAllocRLModule(TorchRLModule, ValueFunctionAPI):
    """Masked logits from a project actor network; values from a pooling encoder of the same observation.

    ``model_config``: ``network`` (attention | pooling), ``hidden``, ``own_features`` and ``task_features`` (the
    observation layout's names, which size the networks and travel into the exported checkpoint) and ``kinds``
    (logits per task: 3 where the environment has release actions; 2 when absent, as in checkpoints from before it).
    """

    def setup(self) -> None:
        cfg = self.model_config
        own_size, task_size, hidden = len(cfg["own_features"]), len(cfg["task_features"]), int(cfg["hidden"])
        self.actor = NETWORKS[cfg["network"]](own_size, task_size, hidden, kinds=int(cfg.get("kinds", 2)))
        for layer in self.actor.output_layers():        # a near-uniform initial policy
            nn.init.orthogonal_(layer.weight, gain=0.01)
            nn.init.zeros_(layer.bias)
        if not self.inference_only:
            self.critic = PoolingEncoder(own_size, task_size, hidden)
            self.value_head = nn.Linear(hidden, 1)

    def _forward(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        obs = batch[Columns.OBS]
        return {Columns.ACTION_DIST_INPUTS: self.actor(obs["observations"].float(), obs["action_mask"] > 0.5)}

    def compute_values(self, batch: dict[str, Any], embeddings: Any = None) -> th.Tensor:
        own, tasks = split_tasks(batch[Columns.OBS]["observations"].float(), self.actor.own_size,
                                 self.actor.task_size)
        return self.value_head(self.critic(own, tasks)[1]).squeeze(-1)
