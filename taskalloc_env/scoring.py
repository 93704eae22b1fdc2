"""Path timing, path score and marginal gains (thesis §3.2.2, eqs. (3.7)–(3.11)), shared by env, policies, solvers.

For a path p of agent i (loc_0 = start position, t_0 = 0), task by task (3.8–3.10):

    arr_r = t_{r-1} + ||pos_j − loc_{r-1}|| / v_i          arrival; feasible only if arr_r < end_j   (3.7)
    st_r  = max(arr_r, e_j)                                 waits for the window (and prerequisites) to open
    t_r   = st_r + dur_j
    reward_r = c̄_j · exp(−λ (st_r − start_j))              (3.8), discount from the task's own start
    cost_r   = γ · d_r                                       (3.9), d_r per ``distance_cost``

(3.8) is printed with the arrival time; discounting from the start st_r (so early arrival never earns more than
c̄_j) is Johnson's Δτ = max(0, τ − τ_start) of §3.4.1. The two ``distance_cost`` readings of d_r are our choice
(see docs/decisions.md). e_j = max(start_j, ready_j) where ready_j is the prerequisite rule of ``prereq_timing``
(our choice: thesis §3.1.3 says prerequisites "must be completed before" j but gives no timing formula):
``conservative`` ready_j = max_m (end_m + dur_m), ``earliest`` max_m (start_m + dur_m), ``none`` −∞. A task
whose e_j is not before end_j can never be started. A pop-up task (``releases``) cannot start before it is
released either: e_j ≥ its release tick × ``mission_time_per_tick`` (our rule; Johnson §4.1.3 gives no mission
clock), so scoring counts only what is feasible after release.

Marginal gain (3.11): c_ij = max_n S(p ⊕_n j) − S(p) over feasible insertions, 0 if none. ``marginal_gain``:
``rescore`` (default, the thesis's (3.11): later tasks are re-timed, their rewards and feasibility re-checked) or
``frozen`` (Johnson §3.3.1 eq. (3.2) and §3.4.1 eq. (3.6): existing service times may not move, which keeps the
score DMG, Johnson (3.13)–(3.19)).
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Sequence
from typing import Any

import numpy as np

from taskalloc_env import kernels
from taskalloc_env.config import TaskAllocConfig
from taskalloc_env.groups import Equipment
from taskalloc_env.kernels.plan import plan_paths, retime_rows
from taskalloc_env.kernels.score import paid_groups
from taskalloc_env.scenario import Scenario


@dataclasses.dataclass(frozen=True)
class Schedule:
    """Timing of one path: arrays aligned with the path ((3.7)–(3.10))."""

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

    def __init__(self, scenario: Scenario, *, distance_cost: str = TaskAllocConfig.distance_cost,
                 prereq_timing: str = TaskAllocConfig.prereq_timing, reward_split: str = TaskAllocConfig.reward_split,
                 marginal_gain: str = TaskAllocConfig.marginal_gain,
                 reward_time: str = TaskAllocConfig.reward_time, travel_metric: str = TaskAllocConfig.travel_metric,
                 release: np.ndarray | None = None) -> None:
        """Scoring options default to the config's defaults (``TaskAllocConfig``), their one home. ``release`` (M,)
        is the mission time at which each task becomes known (None: all at time 0). ``travel_metric`` is the distance
        flown (``distances``): every travel time, cost and flight length derives from the two matrices below."""
        self.scenario = scenario
        self.distance_cost = distance_cost
        self.marginal_gain = marginal_gain
        self.reward_time = reward_time
        s = scenario
        self.lam = float(s.time_discount)
        self.gamma = float(s.distance_discount)
        self.speed = s.agent_speed.astype(float)
        self.dist_agent_task = distances(s.agent_pos, s.task_pos, travel_metric)
        self.dist_task_task = distances(s.task_pos, s.task_pos, travel_metric)
        self.pay = s.task_reward / s.task_agents if reward_split == "total" else s.task_reward.astype(float)
        self.ready = self._prerequisite_ready(prereq_timing)
        self.earliest = np.maximum(s.task_start, self.ready)
        if release is not None:
            self.earliest = np.maximum(self.earliest, release)
        self.deadline = s.task_end
        self.doable = self.earliest < self.deadline
        self.equipment = Equipment(s.agent_equipment, s.task_equipment)
        for array in (self.dist_agent_task, self.dist_task_task, self.pay, self.ready, self.earliest, self.doable):
            array.setflags(write=False)
        # the plan kernels' inputs after the paths, in their order (fixed for the model's life)
        self._kernel_inputs = (self.speed, self.dist_agent_task, self.dist_task_task, self.earliest, self.deadline,
                               self.doable, s.task_duration, s.task_start, self.pay, self.lam, self.gamma,
                               distance_cost == "leg", reward_time == "arrival", marginal_gain == "frozen")

    def _prerequisite_ready(self, prereq_timing: str) -> np.ndarray:
        """ready_j: the earliest time a follow-up may start under ``prereq_timing`` (our choice, see above)."""
        s = self.scenario
        if prereq_timing == "none" or not s.has_prerequisites:
            return np.full(s.n_tasks, -np.inf)
        base = s.task_end if prereq_timing == "conservative" else s.task_start
        done = base + s.task_duration
        return np.where(s.task_prereqs, done[None, :], -np.inf).max(axis=1)

    @classmethod
    def from_config(cls, scenario: Scenario, cfg: TaskAllocConfig, release: np.ndarray | None = None) -> ScoringModel:
        """The scoring model of ``scenario`` under the scoring options of ``cfg`` (the one place it is built);
        ``release`` (M,) the tick each task is released, converted by ``mission_time_per_tick``."""
        mission = None
        if release is not None and cfg.mission_time_per_tick and release.any():
            mission = np.where(release > 0, release * cfg.mission_time_per_tick, -np.inf)
        return cls(scenario, distance_cost=cfg.distance_cost, prereq_timing=cfg.prereq_timing,
                   reward_split=cfg.reward_split, marginal_gain=cfg.marginal_gain, reward_time=cfg.reward_time,
                   travel_metric=cfg.travel_metric, release=mission)

    # -- paths and marginal gains, batched over agents ---------------------------------------------------------
    def schedule(self, agent: int, path: Sequence[int]) -> Schedule:
        """Replay (3.8)–(3.10) along ``path``; ``feasible`` is False if any arrival misses its window."""
        return self.plan([agent], [path], gains=False).timing.schedule(0)

    def insertion_gains(self, agent: int, path: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
        """c_ij and the best slot n_ij of one agent for every task (see ``plan``)."""
        plan = self.plan([agent], [path])
        return plan.gain[0], plan.slot[0]

    def plan(self, agents: Sequence[int], paths: Sequence[Sequence[int]], gains: bool = True) -> Plan:
        """Schedules of ``paths`` and, with ``gains``, c_ij and n_ij (3.11) of every (agent, task), in one pass:
        compiled (``kernels.plan.plan_paths``) when numba is there, else ``plan_reference``."""
        if not kernels.COMPILED:
            return self.plan_reference(agents, paths, gains)
        n_paths = len(paths)
        gain = np.zeros((n_paths, self.scenario.n_tasks))
        slot = np.full((n_paths, self.scenario.n_tasks), -1, dtype=np.int64)
        timing = self._compiled_plan(agents, paths, gains, np.arange(n_paths), gain, slot)
        return Plan(timing, gain, slot)

    def refresh(self, agents: Sequence[int], paths: Sequence[Sequence[int]], table: PathTable, gain: np.ndarray,
                slot: np.ndarray) -> None:
        """Re-time ``paths`` into the rows ``agents`` of ``table`` and recompute those rows of the (N, M) c_ij
        ``gain`` and n_ij ``slot`` arrays, in place (``plan`` then ``PathTable.set_rows``, without the copies)."""
        agents = np.asarray(agents, dtype=np.int64)
        if not kernels.COMPILED:
            plan = self.plan_reference(agents, paths)
            table.set_rows(agents, plan.timing)
            gain[agents], slot[agents] = plan.gain, plan.slot
            return
        cost = retime_rows(*_concatenated(paths), agents, *self._kernel_inputs, gain, slot, table.members,
                           table.reward, table.start)
        table.cost[agents] = cost.sum(axis=1)             # numpy's summation order, as set_rows sums

    def _compiled_plan(self, agents: Sequence[int], paths: Sequence[Sequence[int]], gains: bool, rows: np.ndarray,
                       gain: np.ndarray, slot: np.ndarray) -> Timing:
        """``kernels.plan.plan_paths`` on padded paths: the timing, with c_ij and n_ij written to ``rows``."""
        flat, lengths = _concatenated(paths)
        padded, *timing = plan_paths(flat, lengths, np.asarray(agents, dtype=np.int64), *self._kernel_inputs, gains,
                                     rows, gain, slot)
        return Timing(padded, lengths, *timing)

    def plan_reference(self, agents: Sequence[int], paths: Sequence[Sequence[int]], gains: bool = True) -> Plan:
        """``plan`` in numpy, vectorised over (agent, slot, task) blocks (the reference).

        Paths are padded to a common length P. Timing runs one vectorised step per path position. Gains need no
        loop: inserting j at slot n delays the later tasks; with D the arrival delay at p_n and w_r = st_r − arr_r
        the waiting time at task r, the start delay at r ≥ n is max(0, D − Σ_{q=n..r} w_q). Only the (agent, slot,
        task) triples that are feasible and could still pay (own reward > travel cost) get that suffix evaluated.
        """
        s = self.scenario
        agents = np.asarray(agents, dtype=np.int64)
        padded, lengths, present = _pad(paths)
        count, width = padded.shape
        speed = s.agent_speed[agents]
        from_start = self.dist_agent_task[agents]                                        # (A, M)
        # timing (3.8)-(3.10), position by position
        leg = np.zeros((count, width))
        arrival, start, finish, reward, cost = (np.zeros((count, width)) for _ in range(5))
        feasible = np.ones(count, dtype=bool)
        t = np.zeros(count)
        rows = np.arange(count)
        for r in range(width):
            j = padded[:, r]
            leg[:, r] = from_start[rows, j] if r == 0 else self.dist_task_task[padded[:, r - 1], j]
            arrival[:, r] = t + leg[:, r] / speed
            start[:, r] = np.maximum(arrival[:, r], self.earliest[j])
            finish[:, r] = start[:, r] + s.task_duration[j]
            reward[:, r] = self.pay[j] * np.exp(-self.lam * self._lateness(arrival[:, r], start[:, r], j))
            cost[:, r] = self.gamma * (leg[:, r] if self.distance_cost == "leg" else from_start[rows, j])
            ok = (arrival[:, r] < self.deadline[j]) & self.doable[j]
            feasible &= ok | ~present[:, r]
            t = np.where(present[:, r], finish[:, r], t)
        timing = Timing(padded, lengths, arrival, start, finish, np.where(present, reward, 0.0),
                        np.where(present, cost, 0.0), feasible)
        if not gains:
            return Plan(timing, np.zeros((count, s.n_tasks)), np.full((count, s.n_tasks), -1))
        # inserting j at slot n: leave from loc_n at free_n
        free = np.concatenate([np.zeros((count, 1)), finish], axis=1)                     # (A, P+1)
        to_task = np.concatenate([from_start[:, None, :], self.dist_task_task[padded]], axis=1)  # (A, P+1, M)
        arrive = free[:, :, None] + to_task / speed[:, None, None]
        begin = np.maximum(arrive, self.earliest)
        slots_open = np.arange(width + 1)[None, :] <= lengths[:, None]                   # (A, P+1)
        ok = (arrive < self.deadline) & self.doable & slots_open[:, :, None]
        gain = self.pay * np.exp(-self.lam * self._lateness(arrive, begin, slice(None)))
        if self.distance_cost == "leg":
            detour = to_task.copy()
            detour[:, :width] += np.where(present[:, :, None], self.dist_task_task[padded] - leg[:, :, None], 0.0)
            gain -= self.gamma * detour
        else:
            gain -= self.gamma * from_start[:, None, :]
        ok &= gain > 0                    # later tasks can only lose, so these slots can never pay
        if width:
            # triples (agent, slot n < len(path), task) with a later task to delay
            a_idx, n_idx, j_idx = np.nonzero(ok[:, :width] & present[:, :, None])
            if a_idx.size:
                delay = (begin[a_idx, n_idx, j_idx] + s.task_duration[j_idx]
                         + self.dist_task_task[padded[a_idx, n_idx], j_idx] / speed[a_idx])
                delay = np.maximum(delay - arrival[a_idx, n_idx], 0.0)                        # D, (K,)
                wait = np.where(present, start - arrival, 0.0)
                if self.marginal_gain == "frozen":        # nothing already planned may change: start nor reward
                    fits = delay <= wait[a_idx, n_idx]
                    if self.reward_time == "arrival":
                        ahead = arrival[a_idx, n_idx] - s.task_start[padded[a_idx, n_idx]]
                        fits &= (ahead + delay <= 0) | (delay == 0)
                    ok[a_idx[~fits], n_idx[~fits], j_idx[~fits]] = False
                else:
                    fits, loss = self._propagate_delay(delay, a_idx, n_idx, lengths, arrival, wait, reward, padded)
                    ok[a_idx, n_idx, j_idx] = fits
                    gain[a_idx, n_idx, j_idx] += loss
        gain = np.where(ok, gain, -np.inf)
        slot = np.argmax(gain, axis=1)                                                    # (A, M): earliest slot
        best = np.take_along_axis(gain, slot[:, None, :], axis=1)[:, 0, :]
        best[np.nonzero(present)[0], padded[present]] = 0.0                                # j ∈ p_i: c_ij = 0
        positive = best > 0
        return Plan(timing, np.where(positive, best, 0.0), np.where(positive, slot, -1))


    def _lateness(self, arrival: np.ndarray, start: np.ndarray, tasks: Any) -> np.ndarray:
        """τ − start_j of (3.8): τ the arrival, or the start for ``reward_time="start"``.

        The thesis reads τ as the arrival and pays the full reward for "arriving on time", so an early arrival is not
        paid more: τ = max(arrival, start_j). The two readings differ only when prerequisites hold the start back.
        """
        if self.reward_time == "start":
            return start - self.scenario.task_start[tasks]
        return np.maximum(arrival - self.scenario.task_start[tasks], 0.0)

    def _propagate_delay(self, delay: np.ndarray, a_idx: np.ndarray, n_idx: np.ndarray, lengths: np.ndarray,
                         arrival: np.ndarray, wait: np.ndarray, reward: np.ndarray,
                         padded: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Push each arrival delay D down the path from slot n: feasibility and reward change of the later tasks.

        At later task r the start slips by max(0, d − w_r) (d: its arrival delay, w_r: its waiting time), which is
        the next task's arrival delay. Its reward scales by exp(−λ·slip) (``reward_time="start"``) or by how much
        later than start_j the agent now arrives (``arrival``). A delay absorbed by waiting stops, so only the
        still-delayed triples are carried to the next position.
        """
        fits = np.ones(len(delay), dtype=bool)
        loss = np.zeros(len(delay))
        live = np.arange(len(delay))
        d = delay
        offset = 0
        while live.size:
            a = a_idx[live]
            r = n_idx[live] + offset
            on_path = r < lengths[a]
            live, d, a, r = live[on_path], d[on_path], a[on_path], r[on_path]
            late = d >= self.deadline[padded[a, r]] - arrival[a, r]                 # (3.7) breaks at task r
            fits[live[late]] = False
            slip = d - wait[a, r]
            delayed = slip > 0
            if self.reward_time == "start":
                later = np.maximum(slip, 0.0)
            else:
                ahead = arrival[a, r] - self.scenario.task_start[padded[a, r]]
                later = np.maximum(ahead + d, 0.0) - np.maximum(ahead, 0.0)
            hit = later > 0
            loss[live[hit]] += reward[a[hit], r[hit]] * np.expm1(-self.lam * later[hit])
            carry = delayed & ~late
            live, d = live[carry], slip[carry]
            offset += 1
        return fits, loss


def distances(a: np.ndarray, b: np.ndarray, metric: str = "euclidean") -> np.ndarray:
    """(len(a), len(b)) distances between 3-D points. ``euclidean`` (thesis (3.8)–(3.9)'s ‖·‖):
    ``np.linalg.norm(a[:, None] - b[None], axis=2)`` summed in the same order ((dx² + dy²) + dz²), so the same bits,
    without numpy's slow reduction over an axis of length 3 (a quarter of a millisecond at 100 tasks, once per
    episode); ``manhattan`` (``travel_metric``, ours): |dx| + |dy| + |dz|, the moves of a grid walk."""
    dx, dy, dz = (np.subtract.outer(a[:, c], b[:, c]) for c in range(3))
    if metric == "manhattan":
        return (np.abs(dx) + np.abs(dy)) + np.abs(dz)
    return np.sqrt((dx * dx + dy * dy) + dz * dz)


def _concatenated(paths: Sequence[Sequence[int]]) -> tuple[np.ndarray, np.ndarray]:
    """The paths one after another (the plan kernels' input) and their lengths."""
    lengths = np.fromiter(map(len, paths), dtype=np.int64, count=len(paths))
    flat = np.fromiter(itertools.chain.from_iterable(paths), dtype=np.int64, count=int(lengths.sum()))
    return flat, lengths


def _padded(paths: Sequence[Sequence[int]]) -> tuple[np.ndarray, np.ndarray]:
    """Paths as a zero-padded (A, P) array and their lengths (A,)."""
    lengths = np.array([len(p) for p in paths], dtype=np.int64)
    padded = np.zeros((len(paths), int(lengths.max(initial=0))), dtype=np.int64)
    for a, path in enumerate(paths):
        padded[a, : len(path)] = path
    return padded, lengths


def _pad(paths: Sequence[Sequence[int]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``_padded`` and the (A, P) mask of real entries."""
    padded, lengths = _padded(paths)
    return padded, lengths, np.arange(padded.shape[1])[None, :] < lengths[:, None]


@dataclasses.dataclass(frozen=True)
class Timing:
    """Schedules of a batch of paths as padded (A, P) arrays; ``path`` holds task ids, ``length`` the real sizes."""

    path: np.ndarray
    length: np.ndarray
    arrival: np.ndarray
    start: np.ndarray
    finish: np.ndarray
    reward: np.ndarray      # 0 on padding
    cost: np.ndarray        # 0 on padding
    feasible: np.ndarray    # (A,)

    def schedule(self, a: int) -> Schedule:
        k = int(self.length[a])
        return Schedule(tuple(int(j) for j in self.path[a, :k]), self.arrival[a, :k].copy(),
                        self.start[a, :k].copy(), self.finish[a, :k].copy(), self.reward[a, :k].copy(),
                        self.cost[a, :k].copy(), bool(self.feasible[a]))


@dataclasses.dataclass(frozen=True)
class Plan:
    """Timing of a batch of paths, and each agent's marginal gain and best slot for every task."""

    timing: Timing
    gain: np.ndarray     # (A, M) c_ij
    slot: np.ndarray     # (A, M) n_ij, −1 where c_ij = 0

    @property
    def schedules(self) -> list[Schedule]:
        return [self.timing.schedule(a) for a in range(len(self.gain))]


def prerequisites_valid(scenario: Scenario, valid: np.ndarray) -> np.ndarray:
    """Drop tasks whose prerequisites are not all valid, transitively (our choice; the thesis is silent)."""
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
    """The score of an allocation given as each agent's own path (see ``team_score``)."""

    score: float
    agent_scores: np.ndarray    # (N,)
    members: np.ndarray         # (N, M) bool, own rows
    paid: np.ndarray            # (N, M) bool, member earns the reward
    valid: np.ndarray           # (M,) bool, task completed
    conflicts: np.ndarray       # (M,) bool, more than L_j members


@dataclasses.dataclass
class PathTable:
    """Each agent's own path as (N, M) arrays: membership, reward if paid, start time; and total travel cost."""

    members: np.ndarray     # (N, M) bool
    reward: np.ndarray      # (N, M)
    start: np.ndarray       # (N, M), inf off the path
    cost: np.ndarray        # (N,)

    @classmethod
    def empty(cls, n_agents: int, n_tasks: int) -> PathTable:
        return cls(np.zeros((n_agents, n_tasks), dtype=bool), np.zeros((n_agents, n_tasks)),
                   np.full((n_agents, n_tasks), np.inf), np.zeros(n_agents))

    @classmethod
    def of(cls, schedules: Sequence[Schedule], n_tasks: int) -> PathTable:
        table = cls.empty(len(schedules), n_tasks)
        for i, schedule in enumerate(schedules):
            table.set(i, schedule)
        return table

    def set_rows(self, agents: Sequence[int], timing: Timing) -> None:
        """Overwrite the rows of ``agents`` with the paths of ``timing`` (row a of timing → agent agents[a])."""
        agents = np.asarray(agents, dtype=np.int64)
        self.members[agents] = False
        self.reward[agents] = 0.0
        self.start[agents] = np.inf
        a, r = np.nonzero(np.arange(timing.path.shape[1])[None, :] < timing.length[:, None])
        rows, tasks = agents[a], timing.path[a, r]
        self.members[rows, tasks] = True
        self.reward[rows, tasks] = timing.reward[a, r]
        self.start[rows, tasks] = timing.start[a, r]
        self.cost[agents] = timing.cost.sum(axis=1)

    def set(self, agent: int, schedule: Schedule) -> None:
        path = list(schedule.path)
        self.members[agent] = False
        self.reward[agent] = 0.0
        self.start[agent] = np.inf
        self.members[agent, path] = True
        self.reward[agent, path] = schedule.reward
        self.start[agent, path] = schedule.start
        self.cost[agent] = schedule.cost.sum()


def team_score(model: ScoringModel, paths: Sequence[Schedule] | PathTable,
               conflict_policy: str = "first_L_paid") -> TeamScore:
    """Score = Σ_i Σ_{j∈p_i} (z_j · reward_ij − cost_ij): only valid tasks pay, travel always costs.

    Thesis (3.4) with z_j, §3.1.2 (a failed task provides no score) and §5.3.1 ("the sum of all rewards for
    completed tasks minus the cost of agents travelling"). A task is valid when exactly L_j members hold it ((3.3)),
    their equipment covers te_j ((3.5)) and its prerequisites are valid (our choice). A task with more than L_j
    members is a conflict (after convergence only in a disconnected network, thesis §4.3): under ``first_L_paid``
    its first L_j starters (ties: higher agent id first) are paid if they form a valid group; under ``none_paid``
    nobody is (both our choice).
    """
    s = model.scenario
    table = paths if isinstance(paths, PathTable) else PathTable.of(paths, s.n_tasks)
    members = table.members
    if kernels.COMPILED:
        n, m = members.shape
        paid, valid, conflicts = np.empty((n, m), dtype=bool), np.empty(m, dtype=bool), np.empty(m, dtype=bool)
        paid_groups(members, table.start, s.task_agents, model.equipment.required, model.equipment.agent,
                    model.equipment.any, s.task_prereqs, s.has_prerequisites, conflict_policy == "first_L_paid",
                    paid, valid, conflicts)
    else:
        paid, valid, conflicts = paid_groups_reference(model, table, conflict_policy)
    agent_scores = np.where(paid, table.reward, 0.0).sum(axis=1) - table.cost
    return TeamScore(float(agent_scores.sum()), agent_scores, members.copy(), paid, valid, conflicts)


def paid_groups_reference(model: ScoringModel, table: PathTable,
                          conflict_policy: str = "first_L_paid") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``team_score``'s (N, M) paid members, (M,) valid tasks and conflicts in numpy (the reference of
    ``kernels.score.paid_groups``)."""
    s = model.scenario
    members = table.members
    count = members.sum(axis=0)
    conflicts = count > s.task_agents
    paid = members & (count == s.task_agents)[None, :]
    if conflicts.any() and conflict_policy == "first_L_paid":
        for j in np.flatnonzero(conflicts):
            order = sorted(np.flatnonzero(members[:, j]), key=lambda i: (table.start[i, j], -i))
            paid[order[: s.task_agents[j]], j] = True
    valid = paid.any(axis=0) & model.equipment.covers(paid)
    valid = prerequisites_valid(s, valid)
    paid &= valid[None, :]
    return paid, valid, conflicts
