"""The quit and release conditions of every table, compiled; ``protocol.Protocol.quittable_reference`` and
``Protocol.releasable_reference`` (numpy) are the references.

``quittable`` evaluates thesis Alg 9's timer-free conditions (lines 2–3) and, for the quit options, the timer
(line 6) cell by cell in one pass instead of seven (N, M) numpy operations per bundle-phase step; ``releasable``
the release options under ``release_guard`` (ours).
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.kernels import jit


@jit
def quittable(counts: np.ndarray, task_agents: np.ndarray, own: np.ndarray, quit: np.ndarray, single: np.ndarray,
              assigned_at: np.ndarray, assigned_before: int) -> np.ndarray:
    """(N, M) n_j < L_j, X_i[i][j] > 0, i never quit j, L_j > 1 and H_i[j] < ``assigned_before``."""
    n, m = counts.shape
    out = np.zeros((n, m), dtype=np.bool_)
    for i in range(n):
        for j in range(m):
            out[i, j] = (counts[i, j] < task_agents[j] and own[i, j] > 0 and not quit[i, j] and not single[j]
                         and assigned_at[i, j] < assigned_before)
    return out


# ``release_guard`` as a code (``RELEASE_GUARDS[cfg.release_guard]``)
GUARD_NONE, GUARD_EXCHANGE, GUARD_ONCE = range(3)
RELEASE_GUARDS = {"none": GUARD_NONE, "exchange": GUARD_EXCHANGE, "once": GUARD_ONCE}


@jit
def releasable(in_bundle: np.ndarray, bid_round: np.ndarray, released: np.ndarray, now: int, guard: int,
               out: np.ndarray) -> None:
    """``out`` (N, M): j is in i's bundle and, under ``exchange`` and ``once``, i bid on it before round ``now``;
    under ``once`` i never released it."""
    n, m = in_bundle.shape
    for i in range(n):
        for j in range(m):
            out[i, j] = (in_bundle[i, j] and (guard == GUARD_NONE or bid_round[i, j] < now)
                         and not (guard == GUARD_ONCE and released[i, j]))
