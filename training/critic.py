"""The centralised critic of MAPPO: the value of the global state ``env.state()``, which no actor ever sees.

``env.state()`` (``taskalloc_env.observation.state_vector``) is flat:
``[agent positions (N·3) | agent equipment (N·E) | task positions (M·3) | window starts (M) | window ends (M) |
L_j / N (M) | every agent's own bids (N·M) | round]``. ``state_tokens`` cuts it into one token per agent and one
per task, so that the critic, like the actors, has no weight tied to N or M and one critic serves a mixture of
scenario sizes. The bids become per-task figures (sum, highest, members / L_j, group complete) and per-agent
figures (sum, bundle size / M). ``StateCritic`` embeds both kinds of token, lets them attend to each other (one
Transformer encoder layer, Vaswani et al. 2017) and reads a value out of their mean and max.

The value is what MAPPO's critic learns (Yu et al. 2022, "The Surprising Effectiveness of PPO in Cooperative
Multi-Agent Games", §3: a centralised value function on the global state): the team's return from here, which is
the same for every agent of a copy, since every agent receives the change of the team score.
"""

from __future__ import annotations

import torch as th
from torch import nn

from taskalloc.policies.networks import mlp

TASK_TOKEN = ("x", "y", "z", "window_start", "window_end", "required_agents", "bid_sum", "bid_max", "members",
              "complete", "round")
AGENT_TOKEN = ("x", "y", "z", "bid_sum", "bundle_size", "round")     # then one column per equipment type


def state_size(n_agents: int, n_tasks: int, n_equipment: int) -> int:
    """The width of ``env.state()`` for N agents, M tasks and E equipment types."""
    return n_agents * (3 + n_equipment) + n_tasks * 6 + n_agents * n_tasks + 1


def state_tokens(state: th.Tensor, n_agents: int, n_tasks: int, n_equipment: int
                 ) -> tuple[th.Tensor, th.Tensor]:
    """(B, S) states → agent tokens (B, N, 6 + E) and task tokens (B, M, 11), see the module docstring."""
    n, m, e = n_agents, n_tasks, n_equipment
    if state.shape[-1] != state_size(n, m, e):
        raise ValueError(f"state width {state.shape[-1]} does not fit N={n}, M={m}, E={e}: expected "
                         f"{state_size(n, m, e)}")
    sizes = [n * 3, n * e, m * 3, m, m, m, n * m, 1]
    agent_pos, equipment, task_pos, start, end, required, bids, round_ = th.split(state, sizes, dim=-1)
    b = state.shape[0]
    bids = bids.reshape(b, n, m)
    required_agents = required * n                                          # L_j
    members = (bids > 0).sum(dim=1).float()                                 # (B, M)
    round_m = round_.expand(b, m)
    task = th.stack([*task_pos.reshape(b, m, 3).unbind(-1), start, end, required, bids.sum(dim=1),
                     bids.amax(dim=1), members / required_agents.clamp(min=1), (members >= required_agents).float(),
                     round_m], dim=-1)
    agent = th.cat([agent_pos.reshape(b, n, 3), bids.sum(dim=2, keepdim=True),
                    (bids > 0).sum(dim=2, keepdim=True).float() / m, round_.expand(b, n).unsqueeze(-1),
                    equipment.reshape(b, n, e)], dim=-1)
    return agent, task


class StateCritic(nn.Module):
    """V(state): agent and task tokens, one self-attention layer over all of them, mean and max, an MLP."""

    def __init__(self, n_equipment: int, hidden: int = 64, heads: int = 4) -> None:
        super().__init__()
        self.n_equipment = n_equipment
        self.agents = mlp([len(AGENT_TOKEN) + n_equipment, hidden, hidden], activate_last=False)
        self.tasks = mlp([len(TASK_TOKEN), hidden, hidden], activate_last=False)
        self.mix = nn.TransformerEncoderLayer(hidden, heads, dim_feedforward=2 * hidden, dropout=0.0,
                                              batch_first=True, norm_first=True)
        self.value = mlp([2 * hidden, hidden, 1], activate_last=False)

    def forward(self, state: th.Tensor, n_agents: int, n_tasks: int) -> th.Tensor:
        """(B, S) states → (B,) values."""
        agent, task = state_tokens(state, n_agents, n_tasks, self.n_equipment)
        tokens = self.mix(th.cat([self.agents(agent), self.tasks(task)], dim=1))
        return self.value(th.cat([tokens.mean(dim=1), tokens.amax(dim=1)], dim=-1)).squeeze(-1)
