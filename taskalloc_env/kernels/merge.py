"""The consensus merge of a round, compiled; ``consensus.exchange_reference`` (numpy) is the reference.

``exchange_all`` processes a round's deliveries one message at a time, exactly as ``consensus.exchange`` does with
numpy — the CBBA decision table (``cbba_table.decide``) for single-agent tasks, the two-pass merge
(``group_merge.merge``, ``groups.admit``) for multi-agent tasks, the receiver's timestamps and discovered agents, then
the relayed timestamps of thesis (2.4) — but in compiled loops over the members of each column instead of whole
(receivers × agents × tasks) blocks. Only comparisons and copies happen here, so its results are bit-identical to
the reference; ``tests/test_kernels.py`` checks that on random tables.
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.kernels import jit

NONE = -1


@jit
def _outbids(bid_a: float, agent_a: int, bid_b: float, agent_b: int) -> bool:
    return bid_a > bid_b or (bid_a == bid_b and agent_a > agent_b)


@jit
def _decide(i: int, k: int, z_i: int, y_i: float, z_k: int, y_k: float, s_i: np.ndarray, s_k: np.ndarray,
            canonical: bool) -> int:
    """``cbba_table.decide`` for one task: 0 leave, 1 update, 2 reset."""
    z_i_at = 0 if z_i == NONE else z_i
    z_k_at = 0 if z_k == NONE else z_k
    fresh_zk = s_k[z_k_at] > s_i[z_k_at]
    stale_zk = s_i[z_k_at] > s_k[z_k_at]
    fresh_zi = s_k[z_i_at] > s_i[z_i_at]
    better = _outbids(y_k, z_k, y_i, z_i)
    snd_k, snd_i, snd_none = z_k == k, z_k == i, z_k == NONE
    snd_m = not (snd_k or snd_i or snd_none)
    rcv_i, rcv_k, rcv_none = z_i == i, z_i == k, z_i == NONE
    rcv_third = not (rcv_i or rcv_k or rcv_none)
    rcv_same = rcv_third and z_i == z_k
    rcv_other = rcv_third and z_i != z_k
    update = ((snd_k and rcv_i and better) or (snd_k and rcv_k) or (snd_k and rcv_third and (fresh_zi or better))
              or (snd_k and rcv_none)
              or (snd_m and rcv_i and ((fresh_zk and better) if canonical else (fresh_zk or better)))
              or (snd_m and rcv_k and fresh_zk) or (snd_m and rcv_same and fresh_zk)
              or (snd_m and rcv_other and fresh_zk and (fresh_zi or better)) or (snd_m and rcv_none and fresh_zk)
              or (snd_none and rcv_k) or (snd_none and rcv_third and fresh_zi))
    reset = ((snd_i and rcv_k) or (canonical and snd_i and rcv_third and fresh_zi)
             or (snd_m and rcv_k and not fresh_zk) or (snd_m and rcv_other and fresh_zi and stale_zk))
    if update:
        return 1
    if reset:
        return 2
    return 0


@jit
def _slot_open(column: np.ndarray, newcomer: int, required: np.ndarray, agent_eq: np.ndarray) -> bool:
    """``Equipment.slot_open`` for one column: the newcomer fills an item the members leave unmet."""
    for e in range(required.size):
        if required[e] > 0 and agent_eq[newcomer, e]:
            have = 0
            for m in range(column.size):
                if column[m] > 0 and agent_eq[m, e]:
                    have += 1
            if required[e] > have:
                return True
    return False


@jit
def _replaceable(m: int, newcomer: int, required: np.ndarray, agent_eq: np.ndarray) -> bool:
    for e in range(required.size):  # noqa: SIM110 - compiled: an explicit loop, not a generator
        if required[e] > 0 and agent_eq[m, e] and agent_eq[newcomer, e]:
            return True
    return False


@jit
def _merge_column(out: np.ndarray, sent: np.ndarray, i: int, k: int, s_i: np.ndarray, s_k: np.ndarray,
                  need: int, restricted: bool, required: np.ndarray, agent_eq: np.ndarray,
                  candidate: np.ndarray) -> None:
    """``group_merge.merge`` for one column, in place on ``out`` (the receiver's column); ``candidate`` is
    scratch space of the column's size."""
    n = out.size
    for m in range(n):                                           # pass A: refresh trusted members
        if out[m] > 0 and m != i and (m == k or s_k[m] > s_i[m]):
            out[m] = sent[m]
    for m in range(n):
        candidate[m] = sent[m] > 0 and out[m] == 0 and m != i and (m == k or s_k[m] > s_i[m])
    while True:                                                  # pass B: best (bid, id) newcomer first
        newcomer = -1
        for m in range(n - 1, -1, -1):
            if candidate[m] and (newcomer < 0 or sent[m] > sent[newcomer]):
                newcomer = m
        if newcomer < 0:
            return
        candidate[newcomer] = False
        bid = sent[newcomer]
        count = 0
        for m in range(n):
            if out[m] > 0:
                count += 1
        if count < need and (not restricted or _slot_open(out, newcomer, required, agent_eq)):
            out[newcomer] = bid
            continue
        lowest = -1
        for m in range(n):
            victim = out[m] > 0 and (not restricted or _replaceable(m, newcomer, required, agent_eq))
            if victim and (lowest < 0 or out[m] < out[lowest]):
                lowest = m
        if lowest >= 0 and _outbids(bid, newcomer, out[lowest], lowest):
            out[lowest] = 0.0
            out[newcomer] = bid


@jit
def exchange_all(bids: np.ndarray, winner: np.ndarray, stamps: np.ndarray, known: np.ndarray,
                 snap_bids: np.ndarray, snap_winner: np.ndarray, snap_winning: np.ndarray, snap_stamps: np.ndarray,
                 snap_known: np.ndarray, receiver: np.ndarray, sender: np.ndarray, slot: np.ndarray, now: float,
                 single: np.ndarray, need: np.ndarray, restricted: np.ndarray, required: np.ndarray,
                 agent_eq: np.ndarray, canonical: bool) -> int:
    """Process deliveries (sorted by receiver, send round, sender) in place; returns the informative messages.

    ``snap_*`` stack the snapshots the messages come from; ``slot[d]`` is delivery d's index into them.
    """
    n, _, m = bids.shape
    relayed = np.full((n, n), -np.inf)
    informative = 0
    column = np.empty(n)
    candidate = np.zeros(n, dtype=np.bool_)
    for d in range(receiver.size):
        i, k, q = receiver[d], sender[d], slot[d]
        s_i = stamps[i].copy()
        s_k = snap_stamps[q, k]
        changed = False
        for j in range(m):
            if single[j]:
                z_i = winner[i, j]
                y_i = 0.0 if z_i == NONE else bids[i, z_i, j]
                z_k = snap_winner[q, k, j]
                y_k = snap_winning[q, k, j]
                action = _decide(i, k, z_i, y_i, z_k, y_k, s_i, s_k, canonical)
                if action == 0:
                    continue
                new_z = z_k if action == 1 else NONE
                new_y = y_k if action == 1 else 0.0
                if new_z == z_i and new_y == y_i:
                    continue
                if z_i != NONE:
                    bids[i, z_i, j] = 0.0
                if new_z != NONE:
                    bids[i, new_z, j] = new_y
                winner[i, j] = new_z
                changed = True
            else:
                same = True
                for a in range(n):
                    column[a] = bids[i, a, j]
                    same = same and column[a] == snap_bids[q, k, a, j]
                if same:                    # an identical column: neither pass changes anything
                    continue
                _merge_column(column, snap_bids[q, k, :, j], i, k, s_i, s_k, need[j], restricted[j], required[j],
                              agent_eq, candidate)
                for a in range(n):
                    if column[a] != bids[i, a, j]:
                        bids[i, a, j] = column[a]
                        changed = True
        stamps[i, k] = now
        for a in range(n):
            known[i, a] = known[i, a] or snap_known[q, k, a]
            if snap_stamps[q, k, a] > relayed[i, a]:
                relayed[i, a] = snap_stamps[q, k, a]
        if changed:
            informative += 1
    for i in range(n):
        for a in range(n):
            if relayed[i, a] > stamps[i, a]:
                stamps[i, a] = relayed[i, a]
        stamps[i, i] = now
    return informative
