"""The per-step part of every agent's observation, compiled;
``ObservationBuilder.observe_reference`` (numpy) is the reference.

``step_features`` writes, in one pass over (agent, task), the columns of the task block that change while bids are
made (the bid view's gain, validity, outbid test, group figures and bundle flags; the agent's own bid, quit flags
and quit timer; prerequisites; group completeness) and the agent's own per-step features (bundle size, round,
passed), with the same arithmetic as the reference: the same divisions in float64, integers and flags converted to
float. The results are bit-identical (``tests/test_kernels.py``); the time saved is the twenty strided column writes
and their temporaries per step. The action masks are built in one place, ``engine.action_masks``.
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.kernels import jit

# the task columns ``step_features`` writes, in the order of its ``columns`` argument
COLUMNS = ("gain", "can_bid", "outbid", "members", "lowest_bid", "group_total", "displaced_bid", "in_bundle",
           "own_bid", "quit_before", "can_quit", "rounds_since_change", "prereqs_met", "group_complete")
# the own columns it writes: the bundle size |b_i| / M, the round T / T_max and the passed flag
BUNDLE_SIZE, ROUND, PASSED = 4, 5, 6


@jit
def step_features(out: np.ndarray, columns: np.ndarray, unit: float, gain: np.ndarray, can_bid: np.ndarray,
                  outbid: np.ndarray, members: np.ndarray, task_agents: np.ndarray, lowest_bid: np.ndarray,
                  group_total: np.ndarray, displaced_bid: np.ndarray, in_bundle: np.ndarray, own_bid: np.ndarray,
                  quit: np.ndarray, can_quit: np.ndarray, now: int, assigned_at: np.ndarray,
                  prereqs_met: np.ndarray, own: np.ndarray, bundle_sizes: np.ndarray, round_fraction: float,
                  passed: np.ndarray) -> None:
    """Fill the ``COLUMNS`` of ``out`` (N, M, F) (at the positions ``columns``) from the (N, M) arrays, the own
    columns of ``own`` (N, ≥ 7) from ``bundle_sizes`` |b_i| (N,), the round and ``passed`` (N,)."""
    n, m = gain.shape
    c = columns
    for i in range(n):
        for j in range(m):
            row = out[i, j]
            row[c[0]] = gain[i, j] / unit
            row[c[1]] = can_bid[i, j]
            row[c[2]] = outbid[i, j]
            row[c[3]] = members[i, j] / task_agents[j]
            row[c[4]] = lowest_bid[i, j] / unit
            row[c[5]] = group_total[i, j] / unit
            row[c[6]] = displaced_bid[i, j] / unit
            row[c[7]] = in_bundle[i, j]
            row[c[8]] = own_bid[i, j] / unit
            row[c[9]] = quit[i, j]
            row[c[10]] = can_quit[i, j]
            row[c[11]] = now - assigned_at[i, j] if in_bundle[i, j] else 0
            row[c[12]] = prereqs_met[i, j]
            row[c[13]] = members[i, j] == task_agents[j]
        own[i, BUNDLE_SIZE] = bundle_sizes[i] / m
        own[i, ROUND] = round_fraction
        own[i, PASSED] = passed[i]
