"""SGAMA: the thesis's centralised sequential greedy algorithm for multi-agent assignments (Alg 7, spec cbga §6.7).

Each iteration assigns the one (agent, task) pair with the largest c_ij + Σ_n x_nj (its marginal gain plus the
bids already on the task), among pairs that are eligible (equipment, prerequisites per ``prereq_mode``, a feasible
insertion with c_ij > 0) and where the group has room that the agent's equipment fills. The winner inserts the task
at its best slot and records its bid, the step Alg 7 leaves out. With every L_j = 1 this is SGA (spec cbba §3).
Ties go to the lowest agent id, then the lowest task id (Alg 7 scans agents, then tasks, with a strict ">").
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.allocation import Allocation
from taskalloc_env.bidding import complete_groups, prerequisites_met
from taskalloc_env.config import TaskAllocConfig
from taskalloc_env.group_merge import Equipment
from taskalloc_env.scenario import Scenario
from taskalloc_env.scoring import ScoringModel


def scoring_model(scenario: Scenario, cfg: TaskAllocConfig) -> ScoringModel:
    return ScoringModel(scenario, distance_cost=cfg.distance_cost, prereq_timing=cfg.prereq_timing,
                        reward_split=cfg.reward_split, marginal_gain=cfg.marginal_gain)


def sgama(scenario: Scenario, cfg: TaskAllocConfig | None = None) -> Allocation:
    """Solve ``scenario`` centrally with SGAMA; scored like ``env.evaluate()`` (``cfg`` gives the scoring options)."""
    cfg = cfg or TaskAllocConfig(n_agents=scenario.n_agents, n_tasks=scenario.n_tasks)
    model = scoring_model(scenario, cfg)
    n, m = scenario.n_agents, scenario.n_tasks
    equipment = Equipment(scenario.agent_equipment, scenario.task_equipment)
    match = scenario.eligible()
    paths: list[list[int]] = [[] for _ in range(n)]
    x = np.zeros((n, m))                        # x_ij: the bid agent i placed on task j
    plan = model.plan(range(n), paths)
    gains, slots = plan.gain, plan.slot
    cap = cfg.max_bundle or m
    iterations = 0
    while True:
        members = x > 0
        room = members.sum(axis=0) < scenario.task_agents
        open_slot = equipment.slot_open(np.broadcast_to(members, (n, n, m)),
                                        np.broadcast_to(np.arange(n)[:, None], (n, m)))
        complete = complete_groups(x[None], scenario) if cfg.prereq_mode == "all_complete" else None
        prereqs = prerequisites_met(scenario, cfg.prereq_mode, members.sum(axis=0)[None], complete)[0]
        sizes = np.array([len(p) for p in paths])
        ok = (match & (gains > 0) & ~members & room[None, :] & open_slot & prereqs[None, :]
              & (sizes < cap)[:, None])
        if not ok.any():
            break
        value = np.where(ok, gains + x.sum(axis=0)[None, :], -np.inf)
        i, j = np.unravel_index(int(np.argmax(value)), value.shape)     # row-major: lowest agent, then task
        x[i, j] = gains[i, j]
        paths[i].insert(int(slots[i, j]), int(j))
        gains[i], slots[i] = model.insertion_gains(i, paths[i])
        iterations += 1
    return Allocation.from_paths(model, paths, cfg.conflict_policy, rounds=iterations, bids=iterations)
