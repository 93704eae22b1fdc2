"""A learned round-0 plan, then a bidding policy: the local plan (``research.policies.local_plan``) learned (ours).

In round 0 no message has been exchanged (thesis Alg 5), so an agent's first bundle can only rest on what it knows
itself. ``research.policies.local_plan`` plans that bundle by solving drawn teams around the agent's own start; the
planner trained by ``research.training.planner`` learns the same thing from its observation: for each task, the
probability that the task is on the agent's path in the solver's allocation. ``RoundZeroPlanner`` plays it in round 0
one of two ways (``replan``). Replanning (the default, and every checkpoint without the meta key): at each step it bids
on the most likely task its mask allows while that probability is at least ``threshold``, else passes, estimating afresh
from each state. Planning once, the local plan's way (``replan=False``): at the agent's first round-0 state it fixes its
plan, the allowed tasks at ``threshold`` or above, most likely first (``research.policies.local_plan.planned``), and
bids along it (``research.policies.oracle.bid_along``). The network is fitted on the states of bids along the solver's
path, not along its own estimates, so the later round-0 states a replanning agent reaches are ones it never saw in
training; planning once reads only the first state, the one the local plan reads too. Replanning plays better
(docs/decisions.md, "the round 0 learned"). It passes in every later round; a planner checkpoint names the policy that
takes over (``then``), and ``taskalloc.policies.registry`` loads the pair as one policy, so ``learned:<planner
checkpoint>`` runs anywhere a policy name does. Execution stays decentralised: each agent reads only its own
observation.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from research.policies.local_plan import planned
from research.policies.oracle import bid_along
from taskalloc.policies.base import stack_observations
from taskalloc.policies.checkpoint import Checkpoint, CheckpointError
from taskalloc.policies.learned import LearnedPolicy
from taskalloc_env.actions import bid_columns, n_actions

PLANNER = "round0-planner"      # the checkpoint's meta["algo"] of a planner


def is_threshold(value: Any) -> bool:
    """A probability threshold a planner can bid by: a number strictly between 0 and 1."""
    return not isinstance(value, bool) and isinstance(value, (int, float)) and 0 < value < 1


class RoundZeroPlanner(LearnedPolicy):
    """Round 0: bids on the allowed tasks most likely on its path while that probability is ≥ ``threshold``,
    re-estimated at every step (``replan``) or fixed at the agent's first state; later rounds: passes. The actor's
    bid logits are read as per-task log-odds (``research.training.planner``)."""

    def __init__(self, *args: Any, threshold: float = 0.5, replan: bool = True, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        if not is_threshold(threshold):
            raise ValueError(f"{self.name}: threshold must be a number in (0, 1), got {threshold!r}")
        if not isinstance(replan, bool):
            raise ValueError(f"{self.name}: replan must be true or false, got {replan!r}")
        self.threshold, self.replan = float(threshold), replan
        self.plans: dict[str, tuple[int, ...]] = {}     # agent → its round-0 plan (``replan=False``), per episode

    def start(self, env: Any, seed: int | None = None) -> None:
        super().start(env, seed)
        self.plans = {}

    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        if self.replan or not observations:
            return super().act(observations, infos)
        m, round_column = self.layout.n_tasks, self.layout.own_names.index("round")
        agents = list(observations)
        obs, masks = stack_observations(observations, agents)
        new = [k for k, a in enumerate(agents) if a not in self.plans and obs[k, round_column] == 0]
        if new:
            p = np.where(masks[new, bid_columns(m)] > 0, self.probabilities(self.actor_input(obs[new])), -1.0)
            self.plans.update((agents[k], planned(row, self.threshold)) for k, row in zip(new, p))
        return {a: bid_along(self.plans.get(a, ()), masks[k]) if obs[k, round_column] == 0 else 0
                for k, a in enumerate(agents)}

    def with_rule(self, threshold: float, replan: bool) -> RoundZeroPlanner:
        """The same weights and features, played with another ``threshold`` and ``replan``."""
        return type(self)(self.actor, self.own_features, self.task_features, self.env_overrides, self.meta,
                          deterministic=self.deterministic, name=self.name, threshold=threshold, replan=replan)

    def probabilities(self, obs: np.ndarray) -> np.ndarray:
        """(B, M) the probability that each task is on the agent's path, from the actor's observations (B, D)."""
        import torch as th

        with th.no_grad():
            return th.sigmoid(bid_log_odds(self.actor, th.as_tensor(obs, dtype=th.float32))).numpy().astype(np.float64)

    def decide(self, obs: np.ndarray, masks: np.ndarray) -> np.ndarray:
        m = self.layout.n_tasks
        p = np.where(masks[:, bid_columns(m)] > 0, self.probabilities(obs), -1.0)
        best = p.argmax(axis=1)
        first_round = obs[:, self.layout.own_names.index("round")] == 0     # own features lead every observation
        bid = first_round & (p[np.arange(len(obs)), best] >= self.threshold)
        return np.where(bid, 1 + best, 0)


def bid_log_odds(actor: Any, obs: Any) -> Any:
    """(B, M) tensor: the actor's bid logits with every action unmasked, read as the log-odds that each task is on
    the agent's path (what ``research.training.planner`` fits), for observations (B, D) as a tensor."""
    import torch as th

    m = (obs.shape[1] - actor.own_size) // actor.task_size
    return actor(obs, th.ones(len(obs), n_actions(m), dtype=th.bool))[:, bid_columns(m)]


def planner_meta(checkpoint: Checkpoint, where: str) -> tuple[str, float, bool]:
    """(``then``, ``threshold``, ``replan``) from a planner checkpoint's meta, each checked (a checkpoint without
    ``replan`` replans, as every planner did before the option)."""
    then, threshold = checkpoint.meta.get("then"), checkpoint.meta.get("threshold", 0.5)
    replan = checkpoint.meta.get("replan", True)
    if not isinstance(then, str) or not then:
        raise CheckpointError(f"{where}: a planner checkpoint names the policy that takes over in meta 'then' (a "
                              f"policy name), got {then!r}")
    if not is_threshold(threshold):
        raise CheckpointError(f"{where}: meta 'threshold' must be a number in (0, 1), got {threshold!r}")
    if not isinstance(replan, bool):
        raise CheckpointError(f"{where}: meta 'replan' must be true or false, got {replan!r}")
    return then, float(threshold), replan
