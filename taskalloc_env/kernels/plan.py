"""Path timing and insertion gains, compiled; ``scoring.ScoringModel.plan_reference`` (numpy) is the reference.

``plan_paths`` replays (3.7)–(3.10) along each padded path, then evaluates every insertion (agent, slot, task) of
(3.11) with the same arithmetic, in the same order, as the reference: the delay D that an insertion at slot n
causes, its absorption by the waiting time of later tasks, and the reward those tasks lose (thesis §3.2.2). The
reference evaluates whole (agents × slots × tasks) blocks and then masks; here each insertion stops as soon as it
is known to be infeasible or unprofitable, which is where the time goes in the reference.

The one difference is the exponential: numpy's ``exp``/``expm1`` use SIMD code on CPUs with AVX-512, which can
differ from the C library's (called here) in the last bit. ``tests/test_kernels.py`` compares within 1e-12
relative, and the allocations on random scenarios exactly (``docs/decisions.md``, "compiled kernels").
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.kernels import jit


@jit
def _lateness(arrival: float, start: float, task_start: float, arrival_time: bool) -> float:
    """τ − start_j of (3.8): max(arrival − start_j, 0), or start − start_j for ``reward_time="start"``."""
    if arrival_time:
        return max(arrival - task_start, 0.0)
    return start - task_start


@jit
def _discounted(pay: float, lam: float, lateness: float) -> float:
    """pay · e^{−λ·lateness} of (3.8); on time (lateness 0) that is pay itself, exactly, without the exponential."""
    if lateness == 0.0:
        return pay
    return pay * np.exp(-lam * lateness)


@jit
def _on_path(path: np.ndarray, length: int, j: int) -> bool:
    for r in range(length):  # noqa: SIM110 - compiled: an explicit loop, not a generator
        if path[r] == j:
            return True
    return False


@jit
def plan_paths(flat: np.ndarray, lengths: np.ndarray, agents: np.ndarray, speed: np.ndarray, from_start: np.ndarray,
               dist: np.ndarray, earliest: np.ndarray, deadline: np.ndarray, doable: np.ndarray,
               duration: np.ndarray, task_start: np.ndarray, pay: np.ndarray, lam: float, gamma: float,
               leg_cost: bool, arrival_time: bool, frozen: bool, gains: bool, rows: np.ndarray, gain: np.ndarray,
               slot: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                          np.ndarray]:
    """The paths of ``agents`` (concatenated in ``flat``, ``lengths`` each) timed: the zero-padded (A, P) paths,
    arrival, start, finish, reward and cost arrays and ``feasible`` (A,); with ``gains``, c_ij and n_ij of path a
    written into row ``rows[a]`` of ``gain`` and ``slot``, in place.

    ``speed`` (N,) and ``from_start`` (N, M), every agent's distance to every task, are indexed by ``agents``;
    ``dist`` (M, M) between tasks. Padding entries of the timing arrays stay zero.
    """
    count, m = lengths.size, from_start.shape[1]
    width = 0
    for a in range(count):
        width = max(width, lengths[a])
    padded = np.zeros((count, width), dtype=np.int64)
    at = 0
    for a in range(count):
        for r in range(lengths[a]):
            padded[a, r] = flat[at]
            at += 1
    arrival, start, finish = np.zeros((count, width)), np.zeros((count, width)), np.zeros((count, width))
    reward, cost = np.zeros((count, width)), np.zeros((count, width))
    feasible = np.ones(count, dtype=np.bool_)
    leg = np.zeros(width)
    # with the reward at arrival, τ − start_j ≥ 0 and λ ≥ 0 make the discount e^{-λ(τ − start_j)} ≤ 1 (rewards are
    # ≥ 0), and a delay's loss is ≤ 0: pay_j − charge bounds an insertion's value, so a slot that cannot beat the
    # best so far is skipped before its exponential
    capped = arrival_time and lam >= 0.0
    for a in range(count):
        agent = agents[a]
        t = 0.0
        ok_path = True
        length = lengths[a]
        for r in range(length):                                  # (3.7)–(3.10) along the path
            j = padded[a, r]
            leg[r] = from_start[agent, j] if r == 0 else dist[padded[a, r - 1], j]
            arrival[a, r] = t + leg[r] / speed[agent]
            start[a, r] = max(arrival[a, r], earliest[j])
            finish[a, r] = start[a, r] + duration[j]
            reward[a, r] = _discounted(pay[j], lam, _lateness(arrival[a, r], start[a, r], task_start[j], arrival_time))
            cost[a, r] = gamma * (leg[r] if leg_cost else from_start[agent, j])
            if not (arrival[a, r] < deadline[j] and doable[j]):
                ok_path = False
            t = finish[a, r]
        feasible[a] = ok_path
        if not gains:
            continue
        for j in range(m):                                       # (3.11): the best feasible insertion of j
            if not doable[j] or _on_path(padded[a], length, j):  # no slot is feasible, or j is already planned
                gain[rows[a], j] = 0.0
                slot[rows[a], j] = -1
                continue
            best = -np.inf
            best_slot = 0
            for n in range(length + 1):
                free = 0.0 if n == 0 else finish[a, n - 1]
                if not free < deadline[j]:                      # finish times only grow along the path: no later
                    break                                        # slot can arrive before the deadline either
                to_task = from_start[agent, j] if n == 0 else dist[padded[a, n - 1], j]
                arrive = free + to_task / speed[agent]
                begin = max(arrive, earliest[j])
                if not arrive < deadline[j]:
                    continue
                if leg_cost:
                    detour = to_task
                    if n < length:
                        detour += dist[padded[a, n], j] - leg[n]
                    charge = gamma * detour
                else:
                    charge = gamma * from_start[agent, j]
                if capped and not pay[j] - charge > max(best, 0.0):
                    continue                                     # not even the undiscounted reward would win
                value = _discounted(pay[j], lam, _lateness(arrive, begin, task_start[j], arrival_time))
                value -= charge
                if not value > 0:                                # later tasks can only lose
                    continue
                if n < length:
                    nxt = padded[a, n]
                    delay = begin + duration[j] + dist[nxt, j] / speed[agent]
                    delay = max(delay - arrival[a, n], 0.0)
                    if frozen:                                   # nothing already planned may move
                        fits = delay <= start[a, n] - arrival[a, n]
                        if arrival_time:
                            ahead = arrival[a, n] - task_start[nxt]
                            fits = fits and (ahead + delay <= 0 or delay == 0)
                        if not fits:
                            continue
                    else:                                        # push the delay down the path
                        fits = True
                        loss = 0.0
                        d = delay
                        for r in range(n, length):
                            p = padded[a, r]
                            late = d >= deadline[p] - arrival[a, r]
                            if late:
                                fits = False
                            slip = d - (start[a, r] - arrival[a, r])
                            if arrival_time:
                                ahead = arrival[a, r] - task_start[p]
                                later = max(ahead + d, 0.0) - max(ahead, 0.0)
                            else:
                                later = max(slip, 0.0)
                            if later > 0:
                                loss += reward[a, r] * np.expm1(-lam * later)
                            if not (slip > 0) or late:
                                break
                            d = slip
                        value += loss
                        if not fits:
                            continue
                if value > best:
                    best = value
                    best_slot = n
            if not best > 0:
                gain[rows[a], j] = 0.0
                slot[rows[a], j] = -1
            else:
                gain[rows[a], j] = best
                slot[rows[a], j] = best_slot
    return padded, arrival, start, finish, reward, cost, feasible


@jit
def set_table_rows(rows: np.ndarray, padded: np.ndarray, lengths: np.ndarray, reward: np.ndarray,
                   start: np.ndarray, members: np.ndarray, table_reward: np.ndarray, table_start: np.ndarray) -> None:
    """``PathTable.set_rows`` without the travel cost: path a becomes row ``rows[a]`` of the (N, M) tables."""
    m = members.shape[1]
    for a in range(rows.size):
        i = rows[a]
        for j in range(m):
            members[i, j] = False
            table_reward[i, j] = 0.0
            table_start[i, j] = np.inf
        for r in range(lengths[a]):
            j = padded[a, r]
            members[i, j] = True
            table_reward[i, j] = reward[a, r]
            table_start[i, j] = start[a, r]


@jit
def retime_rows(flat: np.ndarray, lengths: np.ndarray, agents: np.ndarray, speed: np.ndarray, from_start: np.ndarray,
                dist: np.ndarray, earliest: np.ndarray, deadline: np.ndarray, doable: np.ndarray,
                duration: np.ndarray, task_start: np.ndarray, pay: np.ndarray, lam: float, gamma: float,
                leg_cost: bool, arrival_time: bool, frozen: bool, gain: np.ndarray, slot: np.ndarray,
                members: np.ndarray, table_reward: np.ndarray, table_start: np.ndarray) -> np.ndarray:
    """``plan_paths`` of ``agents`` with their gains written to rows ``agents`` of ``gain`` and ``slot``, and their
    timed paths to those rows of the (N, M) path tables (``set_table_rows``), in one call; returns the (A, P) travel
    costs, which the caller sums in numpy's order."""
    padded, _, start, _, reward, cost, _ = plan_paths(flat, lengths, agents, speed, from_start, dist, earliest,
                                                      deadline, doable, duration, task_start, pay, lam, gamma,
                                                      leg_cost, arrival_time, frozen, True, agents, gain, slot)
    set_table_rows(agents, padded, lengths, reward, start, members, table_reward, table_start)
    return cost
