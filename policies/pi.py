"""PI, the performance-impact algorithm (W. Zhao, Q. Meng, P. W. H. Chung, "A heuristic distributed task allocation
method for multivehicle multitask problems and its application to search and rescue scenario", IEEE Trans.
Cybernetics 46(4), 2016), in the closest form this environment's action interface allows (ours; docs/algorithm.md
§10.3 names what differs).

PI's agents share, for each task, its *significance* to its holder: the performance impact of removing the task from
the holder's list (the removal performance impact, RPI). Written for this environment's score (a gain to maximise,
where PI minimises a cost), the significance of task j to agent i holding path p_i is

    ρ_ij = S_i(p_i) − S_i(p_i ⊖ j)          (the score i loses without j; PI's RPI with the sign of a gain)

and the value of including j (PI's inclusion performance impact, IPI) is the marginal gain c_ij (thesis (3.11), with
``marginal_gain = rescore``: the delay j causes to the later tasks counts, as in PI). A PI round is

* inclusion: j is a candidate when c_ij beats the significance of j to its current holder; the agent includes the
  candidate whose inclusion improves the team most, argmax_j (c_ij − ρ_{holder, j}), one at a time;
* consensus on the significances (CBBA's table with the significance as the bid);
* removal: a task whose significance another agent beats is removed, the holder re-evaluating the significances of
  what it keeps.

Here the bid the environment shares is fixed when the bid is made (the marginal gain c_ij, warped), not the holder's
current ρ. So:

* inclusion takes, among the valid bids (the mask: c_ij beats the shared bid y_j, h_ij), the largest c_ij − y_j,
  ties to the lower task id; y_j is the observation's ``group_total`` (for L_j = 1 the holder's bid);
* removal: when a task's shared bid b_ij overstates its current significance (b_ij − ρ_ij > 0, after later
  insertions delayed it), the agent releases it (the release action; the tasks added after it go too) and may bid it
  again at its current value, so that another agent whose value beats the significance can win it in the consensus,
  which then removes it from i (the outbid release). The largest overstatement goes first; each (agent, task) pair
  is released at most once, so the run terminates (our rule, after the thesis's once-per-task quits, §5.2.2).

ρ needs the agent's own path and the tasks' attributes: the policy reads its agent's path and own bids from the agent's
own table (``protocol.knowledge``, row i) and scores them with the environment's scoring model; it reads nothing of
another agent's table.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from taskalloc.policies.base import Policy
from taskalloc_env.actions import PASS, bid_columns, encode_bid, encode_release, release_columns

TOLERANCE = 1e-9        # relative: an overstatement below it is rounding, not a stale bid


class PIPolicy(Policy):
    """PI (Zhao, Meng & Chung 2016) on single-agent tasks: inclusion by the largest improvement over the holder's
    significance, removal of overstated tasks by release actions (``release_actions``)."""

    name = "PI"

    def __init__(self) -> None:
        super().__init__()
        self.released: set[tuple[int, int]] = set()

    @property
    def env_overrides(self) -> dict[str, Any]:
        return {"release_actions": True}

    def start(self, env: Any, seed: int | None = None) -> None:
        super().start(env, seed)
        if self.env.config.task_mix is not None or (self.env.scenario.task_agents > 1).any():
            raise ValueError(f"{self.name} assigns single-agent tasks only (every L_j = 1); use CBGAPolicy for "
                             "L_j > 1")
        self.released = set()

    def significance(self, agent: int) -> dict[int, float]:
        """ρ_ij = S_i(p_i) − S_i(p_i ⊖ j) for every task j on ``agent``'s path (PI's removal performance impact)."""
        model = self.env.protocol.model
        path = self.env.protocol.knowledge.paths[agent]
        whole = model.schedule(agent, path).score
        return {j: whole - model.schedule(agent, [k for k in path if k != j]).score for j in path}

    def removal(self, agent: int, releasable: np.ndarray) -> int | None:
        """The task ``agent`` releases now: the largest overstatement b_ij − ρ_ij > 0 among its releasable tasks it
        never released (lowest task id on ties), or None."""
        own = self.env.protocol.knowledge.groups.own[agent]
        best, best_excess = None, 0.0
        for j, rho in sorted(self.significance(agent).items()):
            excess = float(own[j]) - rho
            if releasable[j] and (agent, j) not in self.released and excess > TOLERANCE * max(1.0, abs(rho)) \
                    and excess > best_excess:
                best, best_excess = j, excess
        return best

    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        m = self.n_tasks
        layout = self.layout
        gain, holder = (layout.own_size + layout.task_column(name) for name in ("gain", "group_total"))
        actions = {}
        for name, observation in observations.items():
            mask = observation["action_mask"].astype(bool)
            agent = self.env.agent_index[name]
            if mask[release_columns(m)].any():
                task = self.removal(agent, mask[release_columns(m)])
                if task is not None:
                    self.released.add((agent, task))
                    actions[name] = int(encode_release(task, m))
                    continue
            valid = mask[bid_columns(m)]
            if not valid.any():
                actions[name] = PASS
                continue
            obs = observation["observation"]
            improvement = obs[gain::layout.task_size][:m] - obs[holder::layout.task_size][:m]
            actions[name] = int(encode_bid(int(np.argmax(np.where(valid, improvement, -np.inf)))))
        return actions
