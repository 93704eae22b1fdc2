"""A first round planned from what one agent knows: how far a decentralised round 0 can get (ours, not in the sources).

In round 0 no message has been exchanged (thesis Alg 5: every agent builds its bundle, then the consensus). An
agent then knows its own start, speed and equipment, the tasks, and how the scenario is drawn
(``taskalloc_env.scenario.generate``: N agents starting uniformly on the floor, thesis §3.3.2), but not where its
teammates start. ``LocalPlanPolicy`` uses exactly that: for agent i it draws ``samples`` teams from the generator,
keeps its own start, solves each drawn instance (exactly, ``taskalloc.policies.centralised.exact``, or where that is out
of reach with the group search ``taskalloc.policies.local_search``, ``solver="lns"``) and plans to bid, in round 0, on
the tasks that i's optimal path holds in at least half of the draws, the most frequent first (a task its action mask
forbids is skipped). From round 1 on it passes: it is meant to be handed over to another policy after round 0
(``research.policies.handover.Handover``; ``python -m research.evaluation.local_plan``).

It is a measurement, like the oracle (``research.policies.oracle``), not a baseline: it costs N × ``samples`` solves
per instance (about 5 s on ``train_small`` with 24 draws and ``exact``; about half a minute on the default scenario with
``lns``, whose search is cut to ``LNS_ITERATIONS`` per draw). What it shows is how close a round 0 played without
hearing anyone can come to the optimum's, which separates what a learned bidder lacks in information from what it lacks
in learning (docs/learning.md). It reads the scenario only for its own agent's row and the tasks; a test checks that
moving the teammates does not change its plan.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from research.policies.oracle import bid_along
from taskalloc.policies.base import Policy
from taskalloc.policies.centralised import exact
from taskalloc.policies.local_search import local_search
from taskalloc_env.allocation import Allocation
from taskalloc_env.config import TaskAllocConfig
from taskalloc_env.scenario import Scenario, generate

THRESHOLD = 0.5     # a task is planned when it is on the agent's optimal path in at least this share of the draws
# the group search per draw: 50 iterations came within 0.05 % of 1 000 on 4 default instances at a tenth of the
# time, and the shares average over the draws anyway (docs/decisions.md)
LNS_ITERATIONS = 50


def lns_draw(scenario: Scenario, cfg: TaskAllocConfig) -> Allocation:
    """The group search's allocation of one drawn team, ``LNS_ITERATIONS`` per start."""
    return local_search(scenario, cfg, iterations=LNS_ITERATIONS)


SOLVERS = {"exact": exact, "lns": lns_draw}


def planned(shares: np.ndarray, threshold: float = THRESHOLD) -> tuple[int, ...]:
    """The tasks of an agent's (M,) ``shares`` at ``threshold`` or above, the most frequent first."""
    return tuple(int(j) for j in np.argsort(-shares, kind="stable") if shares[j] >= threshold)


class LocalPlanPolicy(Policy):
    """Round 0: bids along the tasks its sampled optima give the agent most often; later rounds: passes."""

    def __init__(self, samples: int = 24, solver: str = "exact") -> None:
        super().__init__()
        if isinstance(samples, bool) or not isinstance(samples, int) or samples < 1:
            raise ValueError(f"samples must be an integer >= 1, got {samples!r}")
        if solver not in SOLVERS:
            raise ValueError(f"local plan: unknown solver {solver!r}; known: {', '.join(SOLVERS)}")
        self.samples, self.solver = samples, solver
        self.name = f"local plan ({samples} draws{'' if solver == 'exact' else ', ' + solver})"
        self.team_shares = np.zeros((0, 0))      # (N, M) after start: each agent's shares (``shares``)
        self.plans: tuple[tuple[int, ...], ...] = ()
        # the shares and plans of an instance already played
        self._memo: dict[tuple, tuple[np.ndarray, tuple[tuple[int, ...], ...]]] = {}

    def start(self, env: Any, seed: int | None = None) -> None:
        super().start(env, seed)
        scenario = self.env.scenario
        # the instance's identity (the teammates' starts only tell instances apart; no plan reads them)
        key = (seed, *(a.tobytes() for a in (scenario.agent_pos, scenario.task_pos, scenario.task_start)))
        if key not in self._memo:
            shares = np.array([self.shares(scenario, i, np.random.default_rng([0 if seed is None else seed, i]))
                               for i in range(scenario.n_agents)])
            self._memo[key] = shares, tuple(planned(row) for row in shares)
        self.team_shares, self.plans = self._memo[key]

    def shares(self, scenario: Scenario, agent: int, rng: np.random.Generator) -> np.ndarray:
        """(M,) the share of ``samples`` drawn teams (``agent``'s own start kept) whose solution puts each task on
        ``agent``'s path."""
        cfg, solve = self.env.config, SOLVERS[self.solver]
        counts = np.zeros(scenario.n_tasks)
        for _ in range(self.samples):
            starts = generate(cfg, rng).agent_pos.copy()
            starts[agent] = scenario.agent_pos[agent]
            counts[list(solve(dataclasses.replace(scenario, agent_pos=starts), cfg).paths[agent])] += 1
        return counts / self.samples

    def plan(self, scenario: Scenario, agent: int, rng: np.random.Generator) -> tuple[int, ...]:
        """The tasks ``agent`` bids on in round 0, the most frequent first."""
        return planned(self.shares(scenario, agent, rng))

    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        round_column = self.layout.own_names.index("round")
        actions = {}
        for agent, obs in observations.items():
            plan = self.plans[self.env.agent_index[agent]] if obs["observation"][round_column] == 0 else ()
            actions[agent] = bid_along(plan, obs["action_mask"])
        return actions
