"""Centralised solvers on the same objective as the consensus algorithms: SGAMA and the exact optimum.

Both see the whole scenario at once (no messages, no rounds) and return an ``Allocation`` scored by the same code as
``env.evaluate()``, so every solver is compared on equal terms.

``sgama``: the thesis's centralised sequential greedy algorithm for multi-agent assignments (thesis §3.3.3, Alg 7).
Each iteration assigns the one (agent, task) pair with the largest c_ij + Σ_n x_nj (its marginal gain plus the
bids already on the task), among pairs that are eligible (equipment, prerequisites per ``prereq_mode``, a feasible
insertion with c_ij > 0) and where the group has room that the agent's equipment fills. The winner inserts the task
at its best slot and records its bid, the step Alg 7 leaves out. With every L_j = 1 this is SGA (Johnson §3.3.1).
Ties go to the highest agent id, then the lowest task id: the (bid, agent id) order of CBBA and CBGA (thesis §3.2.3,
Appendix A.1) and the scripted policies' task order, one rule everywhere, so that CBBA = SGA also holds with ties
(Alg 7 as printed scans agents, then tasks, with a strict ">", which would give ties to the lowest agent id).

``exact``: the optimum of the team score (``scoring.team_score``) for small instances, at most ``MAX_AGENTS`` = 6 agents
and ``MAX_TASKS`` = 9 tasks. The time grows with how many tasks one agent can chain: on a 2-core machine,
``train_small`` (4 × 8, L_j ∈ {1, 2}) takes 0.08 s CPU per instance on average (at most 0.23 s over the 200
held-out instances; docs/benchmarks.md, "The exact optimum"), 6 × 9 about a second. Every agent flies its own
path (timing (3.8)–(3.10)), only valid tasks pay, travel always costs. Joining a task that ends up invalid only
costs, so an optimum uses valid tasks only. Two exact steps:

1. per agent, every feasible ordered path by depth-first search (appending a task never changes earlier times),
   keeping the best order of each task subset;
2. dynamic programming over agents on the state "members (and equipment items) per task so far", keeping the best
   total per state; the answer is the best final state in which every task has 0 or exactly L_j members, the
   equipment covers te_j and every prerequisite of a done task is done. One agent's step expands every state by
   every choice as one array operation (``_expand``; ties go to the first (state, choice) pair, the order a loop
   over states and then choices would meet them).
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.allocation import Allocation, Counters
from taskalloc_env.bidding import complete_groups, prerequisites_met
from taskalloc_env.config import TaskAllocConfig
from taskalloc_env.groups import admit
from taskalloc_env.scenario import Scenario, scenario_config
from taskalloc_env.scoring import ScoringModel


def sgama(scenario: Scenario, cfg: TaskAllocConfig | None = None) -> Allocation:
    """Solve ``scenario`` centrally with SGAMA; scored like ``env.evaluate()`` (``cfg`` gives the scoring options)."""
    cfg = cfg or scenario_config(scenario)
    model = ScoringModel.from_config(scenario, cfg)
    n, m = scenario.n_agents, scenario.n_tasks
    match = scenario.eligible()
    paths: list[list[int]] = [[] for _ in range(n)]
    x = np.zeros((n, m))                        # x_ij: the bid agent i placed on task j
    plan = model.plan(range(n), paths)
    gains, slots = plan.gain, plan.slot
    cap = cfg.max_bundle or m
    iterations = 0
    while True:
        members = x > 0
        # Alg 7 fills free slots only: the group admission rule's "room", never a displacement
        room = admit(np.broadcast_to(x, (n, n, m)), np.broadcast_to(np.arange(n)[:, None], (n, m)), gains,
                     scenario.task_agents, model.equipment).room
        complete = complete_groups(x[None], scenario, model.equipment) if cfg.prereq_mode == "all_complete" else None
        prereqs = prerequisites_met(scenario, cfg.prereq_mode, members.sum(axis=0)[None], complete)[0]
        sizes = np.array([len(p) for p in paths])
        ok = (match & (gains > 0) & ~members & room & prereqs[None, :]
              & (sizes < cap)[:, None])
        if not ok.any():
            break
        value = np.where(ok, gains + x.sum(axis=0)[None, :], -np.inf)
        flat = int(np.argmax(value[::-1]))                              # ties: the highest agent, then the lowest task
        i, j = n - 1 - flat // m, flat % m
        x[i, j] = gains[i, j]
        paths[i].insert(int(slots[i, j]), int(j))
        gains[i], slots[i] = model.insertion_gains(i, paths[i])
        iterations += 1
    return Allocation.from_paths(model, paths, cfg.conflict_policy,
                                 counters=Counters(rounds=iterations, bids=iterations))


MAX_AGENTS, MAX_TASKS = 6, 9
CANDIDATES_PER_BLOCK = 1 << 18      # (state, choice) pairs expanded at once: bounds the DP's memory


def _expand(states: np.ndarray, totals: np.ndarray, add: np.ndarray, values: np.ndarray,
            need: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One agent's step of the dynamic programme: every state with every choice that overfills no task, keeping
    the best total per new state (ties: the first in (state, choice) order); states in order of first appearance.
    Returns the new states, their totals and, per new state, the parent state and the choice that led to it."""
    m, n_choices = len(need), len(add)
    rows, sums, flat = [], [], []
    block = max(1, CANDIDATES_PER_BLOCK // max(n_choices, 1))
    for first in range(0, len(states), block):
        cand = states[first: first + block, None, :] + add[None]                      # (B, C, width)
        ok = np.all(cand[:, :, :m] <= need, axis=2)
        p, c = np.nonzero(ok)                                                          # row-major: (state, choice)
        rows.append(cand[p, c])
        sums.append(totals[first + p] + values[c])
        flat.append((first + p) * n_choices + c)
    rows_all, sums_all, flat_all = np.concatenate(rows), np.concatenate(sums), np.concatenate(flat)
    keys = np.ascontiguousarray(rows_all).view(np.dtype((np.void, rows_all.dtype.itemsize * rows_all.shape[1])))
    _, first_seen, group = np.unique(keys.ravel(), return_index=True, return_inverse=True)
    order = np.lexsort((np.arange(len(sums_all)), -sums_all, group))         # per group: best total, then earliest
    starts = np.flatnonzero(np.r_[True, np.diff(group[order]) != 0])
    best = order[starts]                                                       # one per group, in group order
    keep = best[np.argsort(first_seen, kind="stable")]                         # groups in order of first appearance
    return rows_all[keep], sums_all[keep], flat_all[keep] // n_choices, flat_all[keep] % n_choices


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
    cfg = cfg or scenario_config(scenario)
    model = ScoringModel.from_config(scenario, cfg)
    n, m = scenario.n_agents, scenario.n_tasks
    need = scenario.task_agents
    eq = scenario.agent_equipment.astype(np.int64)
    match = scenario.eligible()
    cap = cfg.max_bundle or m
    choices = []
    for i in range(n):
        options = best_paths(model, i, [j for j in range(m) if match[i, j]])
        choices.append([(subset, value, path) for subset, (value, path) in options.items() if len(subset) <= cap])
    k = eq.shape[1]
    # state: members per task, then equipment items per task (task-major); one row per state, its best total
    states, totals = np.zeros((1, m * (1 + k)), dtype=np.int64), np.zeros(1)
    layers = []                     # per agent: (parent state, choice) of every state it leads to
    for i in range(n):
        add = np.zeros((len(choices[i]), m * (1 + k)), dtype=np.int64)
        for c, (subset, _, _) in enumerate(choices[i]):
            idx = np.fromiter(subset, dtype=np.int64, count=len(subset))
            add[c, idx] = 1
            add[c, m + (idx[:, None] * k + np.arange(k)).ravel()] = np.tile(eq[i], len(idx))
        values = np.array([value for _, value, _ in choices[i]])
        states, totals, parent, choice = _expand(states, totals, add, values, need)
        layers.append((parent, choice))
    counts, items = states[:, :m], states[:, m:].reshape(len(states), m, k)
    done = counts == need
    valid = (~np.any((counts > 0) & ~done, axis=1)
             & ~np.any(done & np.any(items < scenario.task_equipment, axis=2), axis=1)
             & ~np.any(done[:, :, None] & scenario.task_prereqs[None] & ~done[:, None, :], axis=(1, 2)))
    best = int(np.argmax(np.where(valid, totals, -np.inf)))   # the empty allocation is always valid
    best_paths_found = [()] * n
    for i in reversed(range(n)):
        parent, choice = layers[i]
        best_paths_found[i] = choices[i][choice[best]][2]
        best = parent[best]
    return Allocation.from_paths(model, [list(p) for p in best_paths_found], cfg.conflict_policy)
