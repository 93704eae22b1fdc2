"""Path timing, path score and marginal gains (spec cbga §3.1–3.2), shared by the env, the policies and the solvers.

For a path p of agent i (loc_0 = start position, t_0 = 0), task by task (3.8–3.10):

    arr_r = t_{r-1} + ||pos_j − loc_{r-1}|| / v_i          arrival; feasible only if arr_r < end_j   (3.7)
    st_r  = max(arr_r, e_j)                                 waits for the window (and prerequisites) to open
    t_r   = st_r + dur_j
    reward_r = c̄_j · exp(−λ (st_r − start_j))              (3.8), discount from the task's own start
    cost_r   = γ · d_r                                       (3.9), d_r per ``distance_cost``

e_j = max(start_j, ready_j) where ready_j is the prerequisite rule of ``prereq_timing`` (spec cbga §1.5):
``conservative`` ready_j = max_m (end_m + dur_m), ``earliest`` max_m (start_m + dur_m), ``none`` −∞. A task whose
e_j is not before end_j can never be started.

Marginal gain (3.11): c_ij = max_n S(p ⊕_n j) − S(p) over feasible insertions, 0 if none. ``marginal_gain``:
``rescore`` (default, the thesis's (3.11): later tasks are re-timed, their rewards and feasibility re-checked) or
``frozen`` (Johnson §1.5: existing start times may not move, which keeps the score DMG).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from taskalloc_env.scenario import Scenario


@dataclasses.dataclass(frozen=True)
class Schedule:
    """Timing of one path: arrays aligned with the path (spec cbga §3.1)."""

    path: tuple[int, ...]
    arrival: np.ndarray
    start: np.ndarray
    finish: np.ndarray
    reward: np.ndarray      # c̄_j e^{−λ(st − start_j)}, paid only if the task is valid
    cost: np.ndarray        # γ d_r, always paid
    feasible: bool

    @property
    def score(self) -> float:
        """S_i(p) (3.10), counting every reward (as agents do when bidding)."""
        return float(self.reward.sum() - self.cost.sum())


class ScoringModel:
    """Scenario-derived arrays and the scoring options; all times and distances precomputed once."""

    def __init__(self, scenario: Scenario, *, distance_cost: str = "leg", prereq_timing: str = "conservative",
                 reward_split: str = "per_agent", marginal_gain: str = "rescore") -> None:
        self.scenario = scenario
        self.distance_cost = distance_cost
        self.marginal_gain = marginal_gain
        s = scenario
        self.lam = s.time_discount
        self.gamma = s.distance_discount
        self.dist_agent_task = np.linalg.norm(s.agent_pos[:, None, :] - s.task_pos[None, :, :], axis=2)
        self.dist_task_task = np.linalg.norm(s.task_pos[:, None, :] - s.task_pos[None, :, :], axis=2)
        self.pay = s.task_reward / s.task_agents if reward_split == "total" else s.task_reward.astype(float)
        self.ready = self._prerequisite_ready(prereq_timing)
        self.earliest = np.maximum(s.task_start, self.ready)
        self.deadline = s.task_end
        self.doable = self.earliest < self.deadline
        for array in (self.dist_agent_task, self.dist_task_task, self.pay, self.ready, self.earliest, self.doable):
            array.setflags(write=False)

    def _prerequisite_ready(self, prereq_timing: str) -> np.ndarray:
        """ready_j: the earliest time a follow-up may start under ``prereq_timing`` (spec cbga §1.5)."""
        s = self.scenario
        if prereq_timing == "none" or not s.has_prerequisites:
            return np.full(s.n_tasks, -np.inf)
        base = s.task_end if prereq_timing == "conservative" else s.task_start
        done = base + s.task_duration
        return np.where(s.task_prereqs, done[None, :], -np.inf).max(axis=1)

    # -- one path --------------------------------------------------------------------------------------------
    def schedule(self, agent: int, path: Sequence[int]) -> Schedule:
        """Replay (3.8)–(3.10) along ``path``; ``feasible`` is False if any arrival misses its window."""
        path = tuple(int(j) for j in path)
        k = len(path)
        arrival, start, finish, reward, cost = (np.zeros(k) for _ in range(5))
        speed = self.scenario.agent_speed[agent]
        t, prev, feasible = 0.0, None, True
        for r, j in enumerate(path):
            leg = self.dist_agent_task[agent, j] if prev is None else self.dist_task_task[prev, j]
            arrival[r] = t + leg / speed
            feasible &= bool(arrival[r] < self.deadline[j]) and bool(self.doable[j])
            start[r] = max(arrival[r], self.earliest[j])
            finish[r] = t = start[r] + self.scenario.task_duration[j]
            reward[r] = self.pay[j] * np.exp(-self.lam * (start[r] - self.scenario.task_start[j]))
            d = leg if self.distance_cost == "leg" else self.dist_agent_task[agent, j]
            cost[r] = self.gamma * d
            prev = j
        return Schedule(path, arrival, start, finish, reward, cost, feasible)

    # -- marginal gains (3.11) ---------------------------------------------------------------------------------
    def insertion_gains(self, agent: int, path: Sequence[int],
                        schedule: Schedule | None = None) -> tuple[np.ndarray, np.ndarray]:
        """c_ij and the best slot n_ij for every task j at once (3.11); 0 and −1 where no insertion is feasible.

        Inserting j at slot n delays the later tasks: with D the arrival delay at p_n and w_r = st_r − arr_r the
        waiting time of task r, the start delay at r ≥ n is max(0, D − Σ_{q=n..r} w_q), so every (slot, task,
        later task) triple is one array element and no Python loop runs over the path.
        """
        sched = schedule if schedule is not None else self.schedule(agent, path)
        path_arr = np.asarray(sched.path, dtype=np.int64)
        k = len(path_arr)
        s = self.scenario
        speed = s.agent_speed[agent]
        free = np.concatenate(([0.0], sched.finish))                                 # (k+1,) departure times
        to_task = np.vstack([self.dist_agent_task[agent][None, :], self.dist_task_task[path_arr]])  # (k+1, M)
        arrive = free[:, None] + to_task / speed
        start = np.maximum(arrive, self.earliest[None, :])
        feasible = (arrive < self.deadline[None, :]) & self.doable[None, :]
        gain = self.pay[None, :] * np.exp(-self.lam * (start - s.task_start[None, :]))
        if self.distance_cost == "leg":
            detour = to_task.copy()
            if k:
                prev_to_next = np.concatenate(([self.dist_agent_task[agent, path_arr[0]]],
                                               self.dist_task_task[path_arr[:-1], path_arr[1:]]))
                detour[:k] += self.dist_task_task[path_arr] - prev_to_next[:, None]
            gain -= self.gamma * detour
        else:
            gain -= self.gamma * self.dist_agent_task[agent][None, :]
        if k:
            # arrival delay D at p_n when j is inserted at slot n < k
            delay = (start[:k] + s.task_duration[None, :] + self.dist_task_task[path_arr] / speed
                     - sched.arrival[:, None])
            delay = np.maximum(delay, 0.0)
            wait = sched.start - sched.arrival
            if self.marginal_gain == "frozen":
                feasible[:k] &= delay <= wait[:, None]
            else:
                cum = np.concatenate(([0.0], np.cumsum(wait)))                     # (k+1,)
                later = np.arange(k)[None, :] >= np.arange(k)[:, None]             # (n, r): r ≥ n
                before_r = np.where(later, cum[None, :k] - cum[:k, None], np.inf)   # waits in [n, r)
                through_r = np.where(later, cum[None, 1:] - cum[:k, None], np.inf)  # waits in [n, r]
                arr_delay = np.maximum(delay[:, :, None] - before_r[:, None, :], 0.0)   # (n, M, r)
                st_delay = np.maximum(delay[:, :, None] - through_r[:, None, :], 0.0)
                slack = self.deadline[path_arr] - sched.arrival                        # (r,)
                feasible[:k] &= np.all(arr_delay < slack[None, None, :], axis=2)
                gain[:k] += np.sum(sched.reward[None, None, :] * np.expm1(-self.lam * st_delay), axis=2)
        gain = np.where(feasible, gain, -np.inf)
        slot = np.argmax(gain, axis=0)
        best = gain[slot, np.arange(s.n_tasks)]
        ok = best > 0
        if k:
            ok[path_arr] = False
        return np.where(ok, best, 0.0), np.where(ok, slot, -1)


def member_matrix(scenario: Scenario, paths: Sequence[Sequence[int]]) -> np.ndarray:
    """(N, M) bool: agent i has task j on its own path (ground truth, spec cbga §1.7)."""
    members = np.zeros((scenario.n_agents, scenario.n_tasks), dtype=bool)
    for i, path in enumerate(paths):
        members[i, list(path)] = True
    return members


def equipment_covered(scenario: Scenario, members: np.ndarray) -> np.ndarray:
    """(M,) te_j ⊆ ⊎ ae_members (multiset inclusion, spec cbga §1.4 (3.5)) for a (N, M) member matrix."""
    have = members.T.astype(np.int64) @ scenario.agent_equipment.astype(np.int64)      # (M, E)
    return np.all(have >= scenario.task_equipment, axis=1)


def prerequisites_valid(scenario: Scenario, valid: np.ndarray) -> np.ndarray:
    """Drop tasks whose prerequisites are not all valid, transitively (spec cbga §1.7 [INF])."""
    valid = valid.copy()
    if not scenario.has_prerequisites:
        return valid
    while True:
        blocked = valid & np.any(scenario.task_prereqs & ~valid[None, :], axis=1)
        if not blocked.any():
            return valid
        valid &= ~blocked


@dataclasses.dataclass(frozen=True)
class TeamScore:
    """The score of an allocation given as each agent's own path (spec cbga §1.7)."""

    score: float
    agent_scores: np.ndarray    # (N,)
    members: np.ndarray         # (N, M) bool, own rows
    paid: np.ndarray            # (N, M) bool, member earns the reward
    valid: np.ndarray           # (M,) bool, task completed
    conflicts: np.ndarray       # (M,) bool, more than L_j members


def team_score(model: ScoringModel, schedules: Sequence[Schedule], conflict_policy: str = "first_L_paid") -> TeamScore:
    """Score = Σ_i Σ_{j∈p_i} (z_j · reward_ij − cost_ij): only valid tasks pay, travel always costs (spec cbga §1.7).

    A task is valid when exactly L_j members hold it, their equipment covers te_j and its prerequisites are valid.
    A task with more than L_j members is a conflict: under ``first_L_paid`` its first L_j starters (ties: higher
    agent id first) are paid if they form a valid group; under ``none_paid`` nobody is.
    """
    s = model.scenario
    n, m = s.n_agents, s.n_tasks
    members = member_matrix(s, [sch.path for sch in schedules])
    start_at = np.full((n, m), np.inf)
    for i, sch in enumerate(schedules):
        start_at[i, list(sch.path)] = sch.start
    count = members.sum(axis=0)
    conflicts = count > s.task_agents
    paid = members & (count == s.task_agents)[None, :]
    if conflicts.any() and conflict_policy == "first_L_paid":
        for j in np.flatnonzero(conflicts):
            order = sorted(np.flatnonzero(members[:, j]), key=lambda i: (start_at[i, j], -i))
            paid[order[: s.task_agents[j]], j] = True
    valid = paid.any(axis=0) & equipment_covered(s, paid)
    valid = prerequisites_valid(s, valid)
    paid &= valid[None, :]
    agent_scores = np.zeros(n)
    for i, sch in enumerate(schedules):
        if sch.path:
            agent_scores[i] = float(sch.reward[paid[i, list(sch.path)]].sum() - sch.cost.sum())
    return TeamScore(float(agent_scores.sum()), agent_scores, members, paid, valid, conflicts)
