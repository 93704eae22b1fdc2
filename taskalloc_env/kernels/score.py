"""Who is paid in a team score, compiled; the numpy lines of ``scoring.team_score`` are the reference.

``paid_groups`` decides, per task, the members that earn its reward: exactly L_j members hold it ((3.3)), or, with
more than L_j (a conflict) and ``first_L_paid``, the first L_j starters (ties: the higher agent id first); the
group's equipment covers te_j ((3.5)); then tasks whose prerequisites are not all valid are dropped, transitively
(the greatest set closed under "every prerequisite is valid": the same set whatever order the tasks are cleared
in). Only counts and comparisons happen here, so the result is identical to the reference; the rewards are summed
by numpy afterwards in both cases (``tests/test_kernels.py``).
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.kernels import jit


@jit
def _first_starters(j: int, count: int, members: np.ndarray, start: np.ndarray, paid: np.ndarray) -> None:
    """Mark the first ``count`` members of task j by start time (ties: the higher id first) as paid."""
    n = members.shape[0]
    for _ in range(count):
        best = -1
        for i in range(n):
            if members[i, j] and not paid[i, j] and (best < 0 or start[i, j] < start[best, j]
                                                     or (start[i, j] == start[best, j] and i > best)):
                best = i
        paid[best, j] = True


@jit
def paid_groups(members: np.ndarray, start: np.ndarray, task_agents: np.ndarray, required: np.ndarray,
                agent_eq: np.ndarray, restricted: bool, prereqs: np.ndarray, has_prereqs: bool, first_l_paid: bool,
                paid: np.ndarray, valid: np.ndarray, conflicts: np.ndarray) -> None:
    """Fill ``paid`` (N, M), ``valid`` and ``conflicts`` (M,) from the (N, M) ``members`` and ``start`` tables."""
    n, m = members.shape
    for j in range(m):
        count = 0
        for i in range(n):
            count += members[i, j]
        conflicts[j] = count > task_agents[j]
        for i in range(n):
            paid[i, j] = members[i, j] and count == task_agents[j]
        if conflicts[j] and first_l_paid:
            _first_starters(j, task_agents[j], members, start, paid)
        ok = False
        for i in range(n):
            ok = ok or paid[i, j]
        if ok and restricted:
            for e in range(required.shape[1]):
                have = 0
                for i in range(n):
                    have += paid[i, j] and agent_eq[i, e]
                if have < required[j, e]:
                    ok = False
                    break
        valid[j] = ok
    if has_prereqs:
        changed = True
        while changed:
            changed = False
            for j in range(m):
                if valid[j]:
                    for p in range(m):
                        if prereqs[j, p] and not valid[p]:
                            valid[j] = False
                            changed = True
                            break
    for j in range(m):
        if not valid[j]:
            for i in range(n):
                paid[i, j] = False
