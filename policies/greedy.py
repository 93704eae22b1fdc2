"""The scripted policies' bundle-building rule, compiled; ``CBGAPolicy.choose_reference`` (numpy) is the reference.

``greedy_actions`` makes, per agent, the choice of ``choose_reference``: the first allowed quit in task order, else
the allowed bid of the largest value (gain, plus the group total, minus the displaced bid with ``net``; the same
additions in the columns' dtype), the lowest task id on ties, else pass. Its argmax keeps ``np.argmax``'s rules (the
first maximum, the first NaN), so the actions are identical (``tests/test_kernels.py``); the time saved is the
dozen small numpy calls a step made on (A, M) arrays.
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.kernels import jit


@jit
def greedy_actions(mask: np.ndarray, gain: np.ndarray, group_total: np.ndarray, displaced_bid: np.ndarray,
                   team_bidding: bool, net: bool, task_quitting: bool) -> np.ndarray:
    """Actions (A,) from masks (A, 1 + 2M) and the (A, M) columns; ``group_total`` is read only with
    ``team_bidding`` and ``displaced_bid`` only with ``net`` too."""
    n, m = gain.shape
    actions = np.zeros(n, dtype=np.int64)
    for i in range(n):
        if task_quitting:
            quit_task = -1
            for j in range(m):
                if mask[i, m + 1 + j]:
                    quit_task = j
                    break
            if quit_task >= 0:
                actions[i] = m + 1 + quit_task
                continue
        best, best_value, any_valid = 0, gain[i, 0], False
        for j in range(m):
            # one expression per case, so the additions run in the columns' dtype as numpy's do
            if team_bidding and net:
                value = gain[i, j] + group_total[i, j] - displaced_bid[i, j]
            elif team_bidding:
                value = gain[i, j] + group_total[i, j]
            else:
                value = gain[i, j]
            if mask[i, 1 + j]:
                any_valid = True
            else:
                value = -np.inf
            if j == 0:
                best_value = value
            elif not np.isnan(best_value) and (value > best_value or np.isnan(value)):
                best, best_value = j, value
        actions[i] = 1 + best if any_valid else 0
    return actions
