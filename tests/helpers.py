"""Shared test helpers: reference computations written from the sources, scenario builders, an episode driver.

The reference functions here are deliberately simple loops over the formulas of thesis §3.2.2 ((3.7)–(3.11)) and
the team score of thesis §5.3.1 (docs/algorithm.md), so that the vectorised implementation is checked against an
independent reading of the sources rather than itself.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from taskalloc_env import Agent, Scenario, Task, TaskAllocEnv
from taskalloc_env.actions import ActionKind, decode
from taskalloc_env.cbba_table import NONE
from taskalloc_env.groups import Equipment
from taskalloc_env.knowledge import LocalKnowledge

TOL = 1e-9

# set by conftest.pytest_configure before the test modules are collected: True for the fast subset (-m "not slow")
FAST_SUBSET = False


def examples(full: int) -> int:
    """Examples a property test draws: ``full`` in the whole suite (CI), a twentieth (at least 10) in the fast
    subset, so the edit-test loop stays under a minute while CI keeps every example."""
    return max(10, full // 20) if FAST_SUBSET else full


# ---------------------------------------------------------------------------------------------------------------
# Reference path timing and score (thesis (3.7)–(3.10); prereq_timing, our choice)
# ---------------------------------------------------------------------------------------------------------------
@dataclass
class Replay:
    path: tuple[int, ...]
    arrival: list[float]
    start: list[float]
    reward: list[float]
    cost: list[float]
    feasible: bool

    @property
    def score(self) -> float:
        return sum(self.reward) - sum(self.cost)


def ready_time(s: Scenario, j: int, prereq_timing: str) -> float:
    """Earliest start allowed by the prerequisites of j (``prereq_timing``, our choice; see docs/decisions.md)."""
    prereqs = np.flatnonzero(s.task_prereqs[j])
    if prereq_timing == "none" or prereqs.size == 0:
        return -math.inf
    if prereq_timing == "conservative":
        return max(float(s.task_end[m] + s.task_duration[m]) for m in prereqs)
    return max(float(s.task_start[m] + s.task_duration[m]) for m in prereqs)


def replay(s: Scenario, agent: int, path: Sequence[int], *, distance_cost: str = "leg",
           prereq_timing: str = "conservative", reward_split: str = "per_agent",
           reward_time: str = "arrival") -> Replay:
    """Walk the path with thesis (3.7)–(3.10), one task at a time; (3.8) discounts from the arrival, no earlier than
    the window's start (``reward_time="arrival"``), or from the start time (``"start"``)."""
    loc = s.agent_pos[agent]
    t = 0.0
    speed = float(s.agent_speed[agent])
    out = Replay(tuple(int(j) for j in path), [], [], [], [], True)
    for j in path:
        leg = float(np.linalg.norm(s.task_pos[j] - loc))
        arr = t + leg / speed
        earliest = max(float(s.task_start[j]), ready_time(s, j, prereq_timing))
        if not arr < s.task_end[j] or not earliest < s.task_end[j]:
            out.feasible = False
        st = max(arr, earliest)
        pay = float(s.task_reward[j]) / (int(s.task_agents[j]) if reward_split == "total" else 1)
        out.arrival.append(arr)
        out.start.append(st)
        late = st - float(s.task_start[j]) if reward_time == "start" else max(arr - float(s.task_start[j]), 0.0)
        out.reward.append(pay * math.exp(-s.time_discount * late))
        d = leg if distance_cost == "leg" else float(np.linalg.norm(s.task_pos[j] - s.agent_pos[agent]))
        out.cost.append(s.distance_discount * d)
        t = st + float(s.task_duration[j])
        loc = s.task_pos[j]
    return out


def reference_gain(s: Scenario, agent: int, path: Sequence[int], j: int, *, marginal_gain: str = "rescore",
                   **scoring) -> tuple[float, int]:
    """(3.11) by brute force: the best feasible insertion of j into path; (0, -1) if none is positive."""
    base = replay(s, agent, path, **scoring)
    best, slot = 0.0, -1
    for n in range(len(path) + 1):
        trial = replay(s, agent, [*path[:n], j, *path[n:]], **scoring)
        if not trial.feasible:
            continue
        if marginal_gain == "frozen":           # nothing planned may change: neither a start time nor a reward
            kept = trial.start[:n] + trial.start[n + 1:]
            paid = trial.reward[:n] + trial.reward[n + 1:]
            if any(abs(a - b) > 1e-9 for a, b in zip(kept, base.start)) or \
                    any(abs(a - b) > 1e-9 for a, b in zip(paid, base.reward)):
                continue
        gain = trial.score - base.score
        if gain > best + 1e-12:
            best, slot = gain, n
    return best, slot


def reference_team_score(s: Scenario, paths: Sequence[Sequence[int]], *, conflict_policy: str = "first_L_paid",
                         **scoring) -> tuple[float, set[int]]:
    """Thesis §5.3.1: rewards of valid tasks minus all travel; returns (score, valid tasks)."""
    replays = [replay(s, i, p, **scoring) for i, p in enumerate(paths)]
    members: dict[int, list[int]] = {j: [] for j in range(s.n_tasks)}
    start_of: dict[tuple[int, int], float] = {}
    for i, r in enumerate(replays):
        for j, st in zip(r.path, r.start):
            members[j].append(i)
            start_of[i, j] = st
    paid: dict[int, list[int]] = {}
    for j, ms in members.items():
        need = int(s.task_agents[j])
        if len(ms) == need:
            paid[j] = ms
        elif len(ms) > need and conflict_policy == "first_L_paid":
            paid[j] = sorted(ms, key=lambda i, j=j: (start_of[i, j], -i))[:need]
    valid = set()
    for j, ms in paid.items():
        have = Counter()
        for i in ms:
            for e in np.flatnonzero(s.agent_equipment[i]):
                have[int(e)] += 1
        if all(have[e] >= int(c) for e, c in enumerate(s.task_equipment[j])):
            valid.add(j)
    changed = True
    while changed:                                    # prerequisites must be valid themselves (transitively)
        changed = False
        for j in list(valid):
            if any(int(m) not in valid for m in np.flatnonzero(s.task_prereqs[j])):
                valid.discard(j)
                changed = True
    total = 0.0
    for i, r in enumerate(replays):
        for j, reward, cost in zip(r.path, r.reward, r.cost):
            if j in valid and i in paid[j]:
                total += reward
            total -= cost
    return total, valid


# ---------------------------------------------------------------------------------------------------------------
# Scenario builders
# ---------------------------------------------------------------------------------------------------------------
def agent(x: float, y: float = 0.0, z: float = 0.0, speed: float = 1.0, equipment: tuple[str, ...] = ()) -> Agent:
    return Agent((float(x), float(y), float(z)), float(speed), tuple(equipment))


def task(x: float, y: float = 0.0, z: float = 0.0, *, reward: float = 100.0, start: float = 100.0,
         end: float | None = None, duration: float = 0.0, agents: int = 1, equipment: tuple[str, ...] = (),
         prerequisites: tuple[int, ...] = ()) -> Task:
    """A task whose window opens late by default, so every agent waits and earns the full reward c̄_j."""
    end = start + 50.0 if end is None else end
    return Task((float(x), float(y), float(z)), float(reward), float(start), float(end),
                float(duration), int(agents), tuple(equipment), tuple(prerequisites))


def build(agents: Sequence[Agent], tasks: Sequence[Task], *, time_discount: float = 0.8,
          distance_discount: float = 10.0, arena: tuple[float, float, float] = (10.0, 10.0, 10.0),
          equipment_names: Sequence[str] | None = None) -> Scenario:
    return Scenario.from_entities(agents, tasks, time_discount=time_discount, distance_discount=distance_discount,
                                  arena=arena, equipment_names=equipment_names)


# ---------------------------------------------------------------------------------------------------------------
# Episode driver with per-step invariant checks
# ---------------------------------------------------------------------------------------------------------------
@dataclass
class Episode:
    allocation: object
    episode_return: float
    steps: int
    quits: Counter = field(default_factory=Counter)          # (agent, task) -> number of quit actions
    bids: int = 0


def run_episode(env: TaskAllocEnv, policy, seed: int | None, *, check: Callable[[TaskAllocEnv], None] | None = None,
                max_steps: int = 100_000) -> Episode:
    """Reset, let ``policy`` act until the episode ends, call ``check(env)`` after reset and after every step."""
    observations, infos = env.reset(seed=seed)
    policy.start(env, seed)
    m = env.config.n_tasks
    total, steps = 0.0, 0
    quits: Counter = Counter()
    bids = 0
    if check is not None:
        check(env)
    while env.agents:
        actions = policy.act({a: observations[a] for a in env.agents}, infos)
        for a, act in actions.items():
            kind, task = decode(act, m)
            if kind is ActionKind.QUIT:
                quits[env.agent_index[a], task] += 1
            elif kind is ActionKind.BID:
                bids += 1
        observations, rewards, _, _, infos = env.step(actions)
        if rewards:
            values = set(rewards.values())
            assert len(values) == 1, f"the reward is cooperative, got {rewards}"
            total += values.pop()
        steps += 1
        if check is not None:
            check(env)
        assert steps < max_steps, "episode did not end"
    return Episode(env.evaluate(), total, steps, quits, bids)


def tables(kn: LocalKnowledge) -> np.ndarray:
    """(N, N, M) every agent's matrix X_i[k][j] as a dense array (``GroupTable.dense``), for small cases."""
    return np.stack([kn.groups.dense(i) for i in range(len(kn.timestamps))])


def check_tables(env: TaskAllocEnv) -> None:
    """Invariants that hold in every agent's local table after every step (docs/algorithm.md)."""
    p = env.protocol
    s = p.scenario
    kn = p.knowledge
    bids = tables(kn)
    n, m = s.n_agents, s.n_tasks
    present = bids > 0
    counts = present.sum(axis=1)
    over = np.argwhere(counts > s.task_agents[None, :])
    assert over.size == 0, f"capacity (thesis (3.4)): agent/task {over.tolist()} has more than L_j members in its table"
    # the group table's layout: members in increasing id order, then cleared empty slots (group_table)
    g = kn.groups
    slots = np.arange(g.members.shape[2])[None, None, :] < g.count[:, :, None]
    assert np.all((g.members >= 0) == slots) and np.all(g.bids[~slots] == 0) and np.all(g.bids[slots] > 0)
    assert np.all((np.diff(g.members, axis=2) > 0) | ~slots[:, :, 1:]), "members out of increasing id order"
    holder = np.arange(n)[:, None, None]
    np.testing.assert_array_equal(g.own, np.where(g.members == holder, g.bids, 0.0).max(axis=2), err_msg="own bids")
    # the single-agent winner (slot 0) agrees with the matrix (one winner per single-agent task)
    for i in range(n):
        for j in np.flatnonzero(s.task_agents == 1):
            holders = np.flatnonzero(present[i, :, j])
            expected = int(holders[0]) if holders.size else NONE
            assert kn.winner[i, j] == expected, f"winner cache of agent {i} task {j}"
    # equipment eligibility of every member in every table (thesis §3.1.3) and no surplus type ((3.5), §3.2.3)
    eligible = s.eligible()
    bad = np.argwhere(present & ~eligible[None, :, :])
    assert bad.size == 0, f"equipment (thesis §3.1.3): (holder, member, task) {bad.tolist()} is not eligible"
    if s.has_equipment and s.agent_equipment.sum(axis=1).max() <= 1:       # single-type agents
        have = np.einsum("ikj,ke->ije", present.astype(int), s.agent_equipment.astype(int))
        restricted = s.task_equipment.any(axis=1)
        surplus = (have > s.task_equipment[None, :, :]) & restricted[None, :, None]
        assert not surplus.any(), f"equipment (thesis (3.5)): surplus type in {np.argwhere(surplus).tolist()}"
    # positive bids never exceed c̄_j (reward ≤ c̄_j and cost ≥ 0, (3.8)–(3.9))
    assert np.all(bids[present] <= np.broadcast_to(s.task_reward, bids.shape)[present] + TOL), "bid above c̄_j"
    cap = env.config.max_bundle or m
    scoring = scoring_options(env)
    for i in range(n):
        b, path = kn.bundles[i], kn.paths[i]
        assert len(set(b)) == len(b), f"duplicate in bundle {b}"
        assert sorted(b) == sorted(path), f"path {path} is not a permutation of bundle {b} (thesis Table 3.1)"
        assert len(b) <= cap
        assert set(b) == set(np.flatnonzero(bids[i, i] > 0).tolist()), \
            f"self-consistency: agent {i} bundle {b} vs own row {np.flatnonzero(bids[i, i] > 0).tolist()}"
        r = replay(s, i, path, **scoring)
        assert r.feasible, f"agent {i} path {path} misses a window ((3.7))"
        check_path_timing(s, i, path, r)


def check_path_timing(s: Scenario, i: int, path: Sequence[int], r: Replay) -> None:
    """Path feasibility ((3.7)): arr < end, st ≥ start, st_{r+1} ≥ st_r + dur_r + leg_{r+1}/v."""
    for q, j in enumerate(path):
        assert r.arrival[q] < s.task_end[j]
        assert s.task_start[j] <= r.start[q] <= s.task_end[j]
        if q:
            prev = path[q - 1]
            leg = float(np.linalg.norm(s.task_pos[j] - s.task_pos[prev]))
            assert r.start[q] >= r.start[q - 1] + s.task_duration[prev] + leg / s.agent_speed[i] - 1e-9


def scoring_options(env: TaskAllocEnv) -> dict:
    c = env.config
    return {"distance_cost": c.distance_cost, "prereq_timing": c.prereq_timing, "reward_split": c.reward_split,
            "reward_time": c.reward_time}


def check_converged_allocation(env: TaskAllocEnv, episode: Episode, *, full_comms: bool = True) -> None:
    """Agreement, self-consistency, equipment, prerequisites, windows and the team score of a finished episode."""
    p = env.protocol
    s = p.scenario
    alloc = episode.allocation
    kn = p.knowledge
    assert alloc.converged, "the run hit the round bound without converging"
    assert p.round <= p.max_rounds
    if full_comms:
        for i in range(1, s.n_agents):
            assert kn.groups.same_table(i, 0), f"agreement (thesis §3.2.3): agent {i} differs from agent 0"
        own = kn.own_bids()
        for k in range(s.n_agents):
            np.testing.assert_array_equal(kn.groups.dense(k), own, err_msg="self-consistency: X_k[i] != X_i[i]")
        assert not alloc.conflicts, f"conflicts under global communication (thesis §4.3): {alloc.conflicts}"
    scoring = scoring_options(env)
    ref_score, ref_valid = reference_team_score(s, alloc.paths, conflict_policy=env.config.conflict_policy, **scoring)
    assert set(alloc.valid_tasks) == ref_valid, f"valid tasks {alloc.valid_tasks} vs reference {sorted(ref_valid)}"
    assert math.isclose(alloc.score, ref_score, rel_tol=1e-9, abs_tol=1e-6), (alloc.score, ref_score)
    assert math.isclose(episode.episode_return * env.reward_scale, alloc.score, rel_tol=1e-9, abs_tol=1e-6), \
        f"episode return {episode.episode_return} × scale {env.reward_scale} != score {alloc.score}"
    if env.reward_scale_rule == "total_reward":          # the score never exceeds the total task reward
        assert episode.episode_return <= 1.0 + 1e-9, f"return {episode.episode_return} above the ceiling 1"
    for j in alloc.valid_tasks:
        members = alloc.members[j]
        assert len(members) == s.task_agents[j]
        have = s.agent_equipment[list(members)].sum(axis=0)
        assert np.all(have >= s.task_equipment[j]), f"valid task {j} lacks equipment ((3.5))"
        for m_ in np.flatnonzero(s.task_prereqs[j]):
            assert int(m_) in alloc.valid_tasks, f"valid task {j} has invalid prerequisite {m_} ((3.6))"
    for i, (path, starts) in enumerate(zip(alloc.paths, alloc.start_times)):
        for j, st in zip(path, starts):
            assert s.task_start[j] - 1e-9 <= st <= s.task_end[j], f"start {st} of task {j} outside its window"
            ready = ready_time(s, j, env.config.prereq_timing)
            assert st >= ready - 1e-9, f"agent {i} starts task {j} at {st} before its prerequisites allow ({ready})"
    for (i, j), count in episode.quits.items():
        assert count <= 1, f"agent {i} quit task {j} {count} times (thesis §5.2.2: once)"


def draw_group_setup(draw: Callable) -> tuple[int, int, int, np.ndarray, np.ndarray, np.ndarray]:
    """For the merge properties (a Hypothesis ``draw``): N agents, M multi-agent tasks, R receivers, L_j per task,
    each agent's one equipment type (N, types) and each task's items (M, types), |te_j| = L_j or none."""
    from hypothesis import strategies as st

    n = draw(st.integers(3, 6))
    m = draw(st.integers(1, 4))
    r = draw(st.integers(1, 3))
    required = np.array([draw(st.integers(2, n)) for _ in range(m)])
    n_types = draw(st.integers(0, 2))
    types = np.array([draw(st.integers(0, max(n_types - 1, 0))) for _ in range(n)])
    agent_eq = np.zeros((n, n_types), dtype=bool)
    if n_types:
        agent_eq[np.arange(n), types] = True
    task_eq = np.zeros((m, n_types), dtype=np.int64)
    for j in range(m):
        if n_types and draw(st.booleans()):
            for _ in range(required[j]):
                task_eq[j, draw(st.integers(0, n_types - 1))] += 1
    return n, m, r, required, agent_eq, task_eq


def episode_digest(args: tuple[str, dict, int]) -> str:
    """(policy name, env overrides, seed) → a hash of every action, reward, info and observation of a
    ``train_small`` episode and its evaluation (module level, so a process pool can run it)."""
    import hashlib
    import json

    from taskalloc.policies import make_policy

    policy_name, overrides, seed = args
    p = make_policy(policy_name)
    env = TaskAllocEnv("train_small", **{**overrides, **p.env_overrides})
    obs, infos = env.reset(seed=seed)
    p.start(env, seed)
    digest = hashlib.sha256()
    while env.agents:
        actions = p.act({a: obs[a] for a in env.agents}, infos)
        obs, rewards, *_, infos = env.step(actions)
        digest.update(json.dumps([actions, rewards, infos], sort_keys=True, default=str).encode())
        for o in obs.values():
            digest.update(o["observation"].tobytes())
    digest.update(repr(env.evaluate()).encode())
    return digest.hexdigest()


def no_equipment(n: int) -> Equipment:
    """N agents and one task, no equipment types."""
    return Equipment(np.zeros((n, 0), dtype=bool), np.zeros((1, 0), dtype=np.int64))


def typed(types: list[str], required: dict[str, int]) -> Equipment:
    """Single-type agents (``types[i]``) and one task requiring the multiset ``required``."""
    names = sorted(set(types) | set(required))
    agent_eq = np.array([[t == name for name in names] for t in types], dtype=bool)
    task_eq = np.array([[required.get(name, 0) for name in names]], dtype=np.int64)
    return Equipment(agent_eq, task_eq)


def assert_same_actions(env: TaskAllocEnv, a, b, seeds: Sequence[int]) -> None:
    """Policies ``a`` and ``b`` take the same actions on every step of whole episodes (``a``'s actions are played)."""
    for seed in seeds:
        observations, infos = env.reset(seed=seed)
        a.start(env, seed)
        b.start(env, seed)
        while env.agents:
            actions = a.act(observations, infos)
            assert actions == b.act(observations, infos)
            observations, _, _, _, infos = env.step(actions)
