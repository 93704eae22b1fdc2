"""The exact optimum of the allocation objective for small instances (up to about 4 agents × 6 tasks).

The objective is the team score of spec cbga §1.7: every agent flies its own path (timing (3.8)–(3.10)), only
valid tasks pay, travel always costs. Joining a task that ends up invalid only costs, so an optimum uses valid
tasks only. Two exact steps:

1. per agent, every feasible ordered path by depth-first search (appending a task never changes earlier times),
   keeping the best order of each task subset;
2. dynamic programming over agents on the state "members (and equipment items) per task so far", keeping the best
   total per state; the answer is the best final state in which every task has 0 or exactly L_j members, the
   equipment covers te_j and every prerequisite of a done task is done.
"""

from __future__ import annotations

import numpy as np

from policies.sgama import scoring_model
from taskalloc_env.allocation import Allocation
from taskalloc_env.config import TaskAllocConfig
from taskalloc_env.scenario import Scenario
from taskalloc_env.scoring import ScoringModel

MAX_AGENTS, MAX_TASKS = 6, 9


def best_paths(model: ScoringModel, agent: int, tasks: list[int]) -> dict[frozenset[int], tuple[float, tuple]]:
    """Best feasible order (score counting every reward, path) of each subset of ``tasks`` the agent can fly.

    Appending a task leaves the earlier times unchanged, so an infeasible prefix prunes all its extensions.
    """
    best: dict[frozenset[int], tuple[float, tuple]] = {frozenset(): (0.0, ())}

    def extend(path: tuple) -> None:
        for j in tasks:
            if j in path:
                continue
            schedule = model.schedule(agent, (*path, j))
            if not schedule.feasible:
                continue
            key = frozenset(schedule.path)
            if key not in best or schedule.score > best[key][0]:
                best[key] = (schedule.score, schedule.path)
            extend(schedule.path)

    extend(())
    return best


def exact(scenario: Scenario, cfg: TaskAllocConfig | None = None) -> Allocation:
    """The optimal allocation of a small ``scenario`` (raises for instances too large to enumerate)."""
    if scenario.n_agents > MAX_AGENTS or scenario.n_tasks > MAX_TASKS:
        raise ValueError(f"exact() enumerates; it takes at most {MAX_AGENTS} agents and {MAX_TASKS} tasks, "
                         f"got {scenario.n_agents} x {scenario.n_tasks}")
    cfg = cfg or TaskAllocConfig(n_agents=scenario.n_agents, n_tasks=scenario.n_tasks)
    model = scoring_model(scenario, cfg)
    n, m = scenario.n_agents, scenario.n_tasks
    need = scenario.task_agents
    eq = scenario.agent_equipment.astype(np.int64)
    match = scenario.eligible()
    cap = cfg.max_bundle or m
    choices = []
    for i in range(n):
        options = best_paths(model, i, [j for j in range(m) if match[i, j]])
        choices.append([(subset, value, path) for subset, (value, path) in options.items() if len(subset) <= cap])
    # state: members per task, then equipment items per task (flattened); value: (total, paths so far)
    start_state = (0,) * m + (0,) * (m * eq.shape[1])
    frontier: dict[tuple, tuple[float, tuple]] = {start_state: (0.0, ())}
    for i in range(n):
        nxt: dict[tuple, tuple[float, tuple]] = {}
        for state, (total, paths) in frontier.items():
            counts = np.array(state[:m])
            items = np.array(state[m:]).reshape(m, -1)
            for subset, value, path in choices[i]:
                idx = list(subset)
                if np.any(counts[idx] + 1 > need[idx]):
                    continue
                new_counts = counts.copy()
                new_counts[idx] += 1
                new_items = items.copy()
                new_items[idx] += eq[i]
                key = tuple(new_counts) + tuple(new_items.ravel())
                cand = total + value
                if key not in nxt or cand > nxt[key][0]:
                    nxt[key] = (cand, (*paths, path))
        frontier = nxt
    best_total, best_paths_found = -np.inf, None
    for state, (total, paths) in frontier.items():
        counts = np.array(state[:m])
        items = np.array(state[m:]).reshape(m, -1)
        done = counts == need
        if np.any((counts > 0) & ~done):
            continue
        if np.any(done & np.any(items < scenario.task_equipment, axis=1)):
            continue
        if np.any(done & np.any(scenario.task_prereqs & ~done[None, :], axis=1)):
            continue
        if total > best_total:
            best_total, best_paths_found = total, paths
    return Allocation.from_paths(model, [list(p) for p in best_paths_found], cfg.conflict_policy)
