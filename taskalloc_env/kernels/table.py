"""Group-table kernels: one write (``set_member``; ``group_table.GroupTable.set_reference`` in Python is the
reference) and the columns a member joined (``joined_members``; ``GroupTable.joined_reference``).

``set_member`` sets X_i[k][j] in the ``GroupTable`` layout (member ids increasing, empty slots last): k joins or
re-bids in task j's column of holder i's table when the value is positive, leaves it otherwise, and the holder's own
bid follows. A bid, a release and a quit each make such writes, one per task, so the call's Python overhead is what
counts; the kernel is a handful of comparisons and copies (the same values as the reference, ``tests/test_kernels.py``).
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.kernels import jit

EMPTY = -1
FULL = -1               # the column already holds L_j other members: the caller raises ``GroupOverflow``


@jit
def set_member(members: np.ndarray, bids: np.ndarray, count: np.ndarray, own: np.ndarray, capacity: np.ndarray,
               i: int, k: int, j: int, value: float) -> int:
    """X_i[k][j] = value in place; returns 1 if the table changed, 0 if not, ``FULL`` (nothing written) if k would
    be member L_j + 1."""
    ids, values = members[i, j], bids[i, j]
    n = count[i, j]
    at = 0
    while at < n and ids[at] < k:
        at += 1
    present = at < n and ids[at] == k
    if value > 0:
        if not present:
            if n >= capacity[j]:
                return FULL
            for c in range(n, at, -1):
                ids[c], values[c] = ids[c - 1], values[c - 1]
            ids[at] = k
            count[i, j] = n + 1
        values[at] = value
    elif present:
        for c in range(at, n - 1):
            ids[c], values[c] = ids[c + 1], values[c + 1]
        ids[n - 1], values[n - 1] = EMPTY, 0.0
        count[i, j] = n - 1
    else:
        return 0
    if k == i:
        own[i, j] = value if value > 0 else 0.0
    return 1


@jit
def joined_members(members: np.ndarray, before: np.ndarray) -> np.ndarray:
    """(N, M) whether (i, j) lists a member that ``before`` (N, M, W) did not list in the same column."""
    n, m, w = members.shape
    out = np.zeros((n, m), dtype=np.bool_)
    for i in range(n):
        for j in range(m):
            for s in range(w):
                k = members[i, j, s]
                if k < 0:
                    continue
                new = True
                for b in range(before.shape[2]):
                    if before[i, j, b] == k:
                        new = False
                        break
                if new:
                    out[i, j] = True
                    break
    return out
