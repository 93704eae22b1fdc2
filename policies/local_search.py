"""Large-neighbourhood search over whole groups: a centralised reference near the optimum where ``exact`` cannot go.

Ours, not in the sources (they compare with SGAMA, thesis §3.3.3, and with the optimum only on small instances).
It gives the benchmark a lower bound on the optimum at every size, so a learned or scripted bidder's score can be
read as a share of what is there to take. Same objective and scoring as every other solver (``scoring.team_score``:
only valid tasks pay, travel always costs), same constraints (time windows (3.7), equipment (3.5), at most
``max_bundle`` tasks per agent); prerequisites are left to the score (a task whose prerequisites are not valid does
not pay, so a move that relies on one is never kept).

A *group* is the set of agents holding one task. Two starts, the empty allocation and SGAMA's, are each refilled
(step 2 without noise, kept if that does not lower the score); then each iteration

1. drops 1–3 random groups (every member's copy of the task);
2. refills greedily with whole groups: among tasks nobody holds, the one whose L_j chosen agents add the most
   marginal gain c_ij (3.11; agents that carry an unmet item of te_j are chosen first, then the largest gains),
   inserted at each member's best slot, until no group adds; in a first refill the group values carry a relative
   noise of ``NOISE`` and, with probability 1/2, the dropped tasks may not return; a second refill without either;
3. keeps the result when the team score does not fall.

The better of the two runs is returned. On the 200 held-out ``train_small`` instances the search reaches 99.85 %
of the exact optimum's total and the optimum itself on 112 (docs/learning.md, "How much there is to take").
Deterministic: the random draws come from ``seed``.
"""

from __future__ import annotations

import numpy as np

from taskalloc.policies.centralised import sgama
from taskalloc_env.allocation import Allocation
from taskalloc_env.config import TaskAllocConfig
from taskalloc_env.scenario import Scenario, scenario_config
from taskalloc_env.scoring import ScoringModel, team_score

ITERATIONS = 1000       # per start; on the default scenario 1000 rather than 200 adds 0.03 % (6 instances)
NOISE = 0.1             # relative noise on the group values of the first refill
MAX_DROPPED = 3         # groups dropped per iteration: 1 to this many


class GroupSearch:
    """The search state of one instance: the scoring model, who may hold what, and the random generator."""

    def __init__(self, scenario: Scenario, cfg: TaskAllocConfig, seed: int) -> None:
        self.scenario = scenario
        self.cfg = cfg
        self.model = ScoringModel.from_config(scenario, cfg)
        self.equipment = self.model.equipment
        self.eligible = scenario.eligible()
        self.cap = cfg.max_bundle or scenario.n_tasks
        self.rng = np.random.default_rng(seed)

    def score(self, paths: list[list[int]]) -> float:
        """The team score of ``paths``, −inf if a path misses a time window."""
        plan = self.model.plan(range(self.scenario.n_agents), paths, gains=False)
        if not plan.timing.feasible.all():
            return -np.inf
        return team_score(self.model, plan.schedules, self.cfg.conflict_policy).score

    def group(self, task: int, gain: np.ndarray) -> np.ndarray | None:
        """L_j agents for ``task`` (carriers of unmet items first, then the largest gains), or None if none fit."""
        need = int(self.scenario.task_agents[task])
        candidates = [int(i) for i in np.argsort(-gain, kind="stable") if np.isfinite(gain[i])]
        if len(candidates) < need:
            return None
        if not self.equipment.restricted[task]:
            return np.array(candidates[:need])
        members = np.zeros((self.scenario.n_agents, self.scenario.n_tasks), dtype=bool)
        for _ in range(need):
            unmet = self.equipment.required[task] > self.equipment.items(members)[task]
            pick = next((i for i in candidates if np.any(unmet & self.equipment.agent[i])), candidates[0])
            members[pick, task] = True
            candidates.remove(pick)
        return np.flatnonzero(members[:, task]) if self.equipment.covers(members)[task] else None

    def refill(self, paths: list[list[int]], noise: float, barred: set[int]) -> list[list[int]]:
        """Insert the most valuable whole group among the tasks nobody holds, until no group adds anything."""
        n, m = self.scenario.n_agents, self.scenario.n_tasks
        while True:
            plan = self.model.plan(range(n), paths)
            held = np.zeros((n, m), dtype=bool)
            for i, path in enumerate(paths):
                held[i, path] = True
            room = np.array([len(p) for p in paths]) < self.cap
            gain = np.where(self.eligible & room[:, None] & (plan.slot >= 0), plan.gain, -np.inf)
            best_value, best = 0.0, None
            for task in np.flatnonzero(~held.any(axis=0)):
                if task in barred:
                    continue
                members = self.group(int(task), gain[:, task])
                if members is None:
                    continue
                value = gain[members, task].sum() * (1 + noise * self.rng.standard_normal())
                if value > best_value:
                    best_value, best = value, (int(task), members)
            if best is None:
                return paths
            task, members = best
            paths = [list(p) for p in paths]
            for i in members:
                paths[i].insert(int(plan.slot[i, task]), task)

    def run(self, start: list[list[int]], iterations: int) -> tuple[list[list[int]], float]:
        """Search from ``start``; the best paths found and their team score."""
        current, current_score = [list(p) for p in start], self.score(start)
        filled = self.refill(current, 0.0, set())
        filled_score = self.score(filled)
        if filled_score >= current_score:           # a group whose prerequisites never pay may lower the score
            current, current_score = filled, filled_score
        for _ in range(iterations):
            held = sorted({j for path in current for j in path})
            if not held:
                break
            count = min(int(self.rng.integers(1, MAX_DROPPED + 1)), len(held))
            dropped = set(self.rng.choice(held, size=count, replace=False).tolist())
            trial = [[j for j in path if j not in dropped] for path in current]
            trial = self.refill(trial, NOISE, dropped if self.rng.random() < 0.5 else set())
            trial = self.refill(trial, 0.0, set())
            score = self.score(trial)
            if score >= current_score:
                current, current_score = trial, score
        return current, current_score


def local_search(scenario: Scenario, cfg: TaskAllocConfig | None = None, iterations: int = ITERATIONS,
                 seed: int = 0) -> Allocation:
    """The best allocation the group search finds from the empty allocation and from SGAMA's."""
    if iterations < 0:
        raise ValueError(f"local_search: iterations must be ≥ 0, got {iterations}")
    cfg = cfg or scenario_config(scenario)
    search = GroupSearch(scenario, cfg, seed)
    starts = ([[] for _ in range(scenario.n_agents)], [list(p) for p in sgama(scenario, cfg).paths])
    runs = [search.run(start, iterations) for start in starts]
    paths, _ = max(runs, key=lambda run: run[1])            # ties: the first start
    return Allocation.from_paths(search.model, paths, cfg.conflict_policy)
