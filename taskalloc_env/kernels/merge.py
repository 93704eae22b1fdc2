"""The consensus merge of a round, compiled; ``consensus.exchange_reference`` (numpy) is the reference.

``exchange_all`` processes a round's deliveries one message at a time, exactly as ``consensus.exchange`` does with
numpy — the CBBA decision table (``cbba_table.decide``) for single-agent tasks, the two-pass merge
(``group_merge.merge``, ``groups.admit``) for multi-agent tasks, the receiver's timestamps and discovered agents, then
the relayed timestamps of thesis (2.4) — but in compiled loops over the members of each column, read from the
senders' snapshots and written to the receivers' tables in the ``GroupTable`` layout itself, instead of whole
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
def _replaceable(m: int, newcomer: int, required: np.ndarray, agent_eq: np.ndarray) -> bool:
    for e in range(required.size):  # noqa: SIM110 - compiled: an explicit loop, not a generator
        if required[e] > 0 and agent_eq[m, e] and agent_eq[newcomer, e]:
            return True
    return False


@jit(inline=True)
def _value_of(agent: int, count: int, ids: np.ndarray, values: np.ndarray) -> float:
    """The bid of ``agent`` in a member list (0 if it is not a member)."""
    for c in range(count):
        if ids[c] == agent:
            return values[c]
    return 0.0


@jit
def _list_slot_open(count: int, ids: np.ndarray, newcomer: int, required: np.ndarray, agent_eq: np.ndarray) -> bool:
    """``Equipment.slot_open`` on a member list."""
    for e in range(required.size):
        if required[e] > 0 and agent_eq[newcomer, e]:
            have = 0
            for c in range(count):
                if agent_eq[ids[c], e]:
                    have += 1
            if required[e] > have:
                return True
    return False


@jit(inline=True)
def _any_trusted(count: int, ids: np.ndarray, i: int, k: int, s_i: np.ndarray, s_k: np.ndarray) -> bool:
    """Some member other than the receiver i is the sender k or was heard of more recently by k than by i."""
    for c in range(count):
        m = ids[c]
        if m != i and (m == k or s_k[m] > s_i[m]):
            return True
    return False


@jit(inline=True)
def _merge_members(count: int, ids: np.ndarray, values: np.ndarray, sent_count: int, sent_ids: np.ndarray,
                   sent_values: np.ndarray, i: int, k: int, s_i: np.ndarray, s_k: np.ndarray, need: int,
                   restricted: bool, required: np.ndarray, agent_eq: np.ndarray, taken: np.ndarray) -> int:
    """``group_merge.merge`` for one column held as member lists, in place on the receiver's (``ids``,
    ``values``, kept in increasing id order); returns its new member count. ``taken`` is scratch space."""
    kept = 0
    for c in range(count):                                       # pass A: refresh trusted members
        m, v = ids[c], values[c]
        if m != i and (m == k or s_k[m] > s_i[m]):
            v = _value_of(m, sent_count, sent_ids, sent_values)
        if v > 0:
            ids[kept], values[kept] = m, v
            kept += 1
    count = kept
    for c in range(sent_count):                                  # pass B candidates: trusted non-members
        m = sent_ids[c]
        taken[c] = m == i or not (m == k or s_k[m] > s_i[m]) or _value_of(m, count, ids, values) > 0
    while True:                                                  # best (bid, id) newcomer first
        best = -1
        for c in range(sent_count - 1, -1, -1):
            if not taken[c] and (best < 0 or sent_values[c] > sent_values[best]):
                best = c
        if best < 0:
            return count
        taken[best] = True
        newcomer, bid = sent_ids[best], sent_values[best]
        if count < need and (not restricted or _list_slot_open(count, ids, newcomer, required, agent_eq)):
            count = _insert(count, ids, values, newcomer, bid)
            continue
        lowest = -1
        for c in range(count):
            victim = not restricted or _replaceable(ids[c], newcomer, required, agent_eq)
            if victim and (lowest < 0 or values[c] < values[lowest]):
                lowest = c
        if lowest >= 0 and _outbids(bid, newcomer, values[lowest], ids[lowest]):
            for c in range(lowest, count - 1):                   # drop the displaced member
                ids[c], values[c] = ids[c + 1], values[c + 1]
            count = _insert(count - 1, ids, values, newcomer, bid)


@jit(inline=True)
def _insert(count: int, ids: np.ndarray, values: np.ndarray, agent: int, value: float) -> int:
    """Insert (agent, value) into a member list kept in increasing id order; returns the new count."""
    c = count
    while c > 0 and ids[c - 1] > agent:
        ids[c], values[c] = ids[c - 1], values[c - 1]
        c -= 1
    ids[c], values[c] = agent, value
    return count + 1


@jit(inline=True)
def _same_members(count_a: int, ids_a: np.ndarray, values_a: np.ndarray, count_b: int, ids_b: np.ndarray,
                  values_b: np.ndarray) -> bool:
    if count_a != count_b:
        return False
    for c in range(count_a):  # noqa: SIM110 - compiled: an explicit loop, not a generator
        if ids_a[c] != ids_b[c] or values_a[c] != values_b[c]:
            return False
    return True


@jit(inline=True)
def _listed(agent: int, count: int, ids: np.ndarray) -> bool:
    """``agent`` is in a member list."""
    for c in range(count):  # noqa: SIM110 - compiled: an explicit loop, not a generator
        if ids[c] == agent:
            return True
    return False


@jit
def _own_tasks(sent_count: np.ndarray, sent_ids: np.ndarray, single: np.ndarray, n: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """For each sent table (stacked (q, k) as t = q · N + k): the multi-agent tasks its sender k is a member of."""
    h, m = sent_count.shape
    count = np.zeros(h, dtype=np.int64)
    tasks = np.empty((h, m), dtype=np.int64)
    for t in range(h):
        k = t % n
        for j in range(m):
            if not single[j] and _listed(k, sent_count[t, j], sent_ids[t, j]):
                tasks[t, count[t]] = j
                count[t] += 1
    return count, tasks


@jit
def _only_sender(i: int, k: int, s_i: np.ndarray, s_k: np.ndarray) -> bool:
    """k is the only agent other than i that i must trust from k: k heard of no other agent more recently than i."""
    for a in range(s_i.size):  # noqa: SIM110 - compiled: an explicit loop, not a generator
        if a != i and a != k and s_k[a] > s_i[a]:
            return False
    return True


@jit(inline=True)
def _kept_by_sender(count: int, ids: np.ndarray, values: np.ndarray, sent_count: int, sent_ids: np.ndarray,
                    sent_values: np.ndarray, k: int) -> bool:
    """A merge that trusts only the sender k leaves this column as it is: every member's bid is positive (pass A
    keeps the untrusted ones) and k is a member on both sides with the same bid (pass A keeps it, pass B has no
    newcomer) or on neither (nothing to refresh, no newcomer)."""
    mine, listed = 0.0, False
    for c in range(count):
        if not values[c] > 0:
            return False
        if ids[c] == k:
            mine, listed = values[c], True
    for c in range(sent_count):
        if sent_ids[c] == k:
            return listed and sent_values[c] == mine
    return not listed


@jit
def _columns_to_visit(count_i: np.ndarray, ids_i: np.ndarray, single: np.ndarray, sender_tasks: np.ndarray,
                      sender_count: int, only_sender: bool, k: int, visit: np.ndarray) -> int:
    """The columns a message from k to i can change, into ``visit``; returns how many.

    A multi-agent column changes only through a member that i must trust from k (``_any_trusted``): k itself, or an
    agent k heard of more recently than i. When k is the only such agent (``only_sender``: on a connected network
    after the first rounds, nearly always), only the columns where k is a member in i's table or in k's can change;
    every column otherwise. Single-agent columns are always visited (the CBBA table decides them). Order does not
    matter: a message's columns are merged independently."""
    m = count_i.size
    visits = 0
    for j in range(m):
        if not only_sender or single[j] or _listed(k, count_i[j], ids_i[j]):
            visit[visits] = j
            visits += 1
    if only_sender:
        for c in range(sender_count):
            j = sender_tasks[c]
            if not _listed(k, count_i[j], ids_i[j]):    # not listed yet (k is no member in i's column)
                visit[visits] = j
                visits += 1
    return visits


@jit
def exchange_all(count: np.ndarray, ids: np.ndarray, values: np.ndarray, own: np.ndarray, stamps: np.ndarray,
                 known: np.ndarray, snap_count: np.ndarray, snap_ids: np.ndarray, snap_values: np.ndarray,
                 snap_stamps: np.ndarray, snap_known: np.ndarray, receiver: np.ndarray, sender: np.ndarray,
                 slot: np.ndarray, now: float, single: np.ndarray, need: np.ndarray, restricted: np.ndarray,
                 required: np.ndarray, agent_eq: np.ndarray, canonical: bool) -> int:
    """Process deliveries (sorted by receiver, send round, sender) in place; returns the informative messages.

    The receivers' groups are the ``GroupTable`` arrays (``count`` (N, M), member ``ids`` and their bid ``values``
    (N, M, W), ids increasing, empty slots EMPTY/0, and each holder's ``own`` bids (N, M)), written in place in the
    same layout. ``snap_*`` stack the snapshots the messages come from ((Q, N, …)); ``slot[d]`` is delivery d's
    index into them. A single-agent task's winner and bid are slot 0; a multi-agent column is a member list of at
    most L_j, so a message costs O(M · L), not O(M · N).
    """
    n, m, width = ids.shape
    relayed = np.full((n, n), -np.inf)
    informative = 0
    sent_count = snap_count.reshape(-1, m)
    sent_ids = snap_ids.reshape(-1, m, width)
    sent_values = snap_values.reshape(-1, m, width)
    own_count, own_tasks = _own_tasks(sent_count, sent_ids, single, n)
    before_ids = np.empty(width, dtype=np.int64)
    before_values = np.empty(width)
    taken = np.zeros(width, dtype=np.bool_)
    visit = np.empty(m, dtype=np.int64)
    s_i = np.empty(n)
    for d in range(receiver.size):
        i, k, q = receiver[d], sender[d], slot[d]
        t = q * n + k                                            # the sender's table in the stacked snapshots
        s_i[:] = stamps[i]
        s_k = snap_stamps[q, k]
        changed = False
        only_sender = _only_sender(i, k, s_i, s_k)
        visits = _columns_to_visit(count[i], ids[i], single, own_tasks[t], own_count[t], only_sender, k, visit)
        for x in range(visits):
            j = visit[x]
            if single[j]:
                z_i = ids[i, j, 0]
                y_i = values[i, j, 0]
                z_k = sent_ids[t, j, 0]
                y_k = sent_values[t, j, 0]
                if z_k == z_i and y_k == y_i:
                    continue                # the same entry: an update rewrites it, a reset needs z_k ≠ z_i
                action = _decide(i, k, z_i, y_i, z_k, y_k, s_i, s_k, canonical)
                if action == 0:
                    continue
                new_z = z_k if action == 1 else NONE
                new_y = y_k if action == 1 else 0.0
                if new_z == z_i and new_y == y_i:
                    continue
                ids[i, j, 0] = new_z
                values[i, j, 0] = 0.0 if new_z == NONE else new_y
                count[i, j] = 0 if new_z == NONE else 1
                own[i, j] = new_y if new_z == i else 0.0
                changed = True
                continue
            c_i, c_k = count[i, j], sent_count[t, j]
            if _same_members(c_i, ids[i, j], values[i, j], c_k, sent_ids[t, j], sent_values[t, j]):
                continue                    # an identical column: neither pass changes anything
            if only_sender and _kept_by_sender(c_i, ids[i, j], values[i, j], c_k, sent_ids[t, j], sent_values[t, j], k):
                continue                    # k's bid is the same on both sides and nobody else is trusted
            if not (_any_trusted(c_i, ids[i, j], i, k, s_i, s_k) or _any_trusted(c_k, sent_ids[t, j], i, k, s_i, s_k)):
                continue                    # both passes act on trusted members only: nothing can change
            for c in range(c_i):
                before_ids[c], before_values[c] = ids[i, j, c], values[i, j, c]
            c_new = _merge_members(c_i, ids[i, j], values[i, j], c_k, sent_ids[t, j], sent_values[t, j], i, k,
                                   s_i, s_k, need[j], restricted[j], required[j], agent_eq, taken)
            count[i, j] = c_new
            for c in range(c_new, width):                        # the empty slots, cleared (canonical layout)
                ids[i, j, c], values[i, j, c] = NONE, 0.0
            same = c_new == c_i
            for c in range(c_i if same else 0):
                same = same and ids[i, j, c] == before_ids[c] and values[i, j, c] == before_values[c]
            if not same:
                own[i, j] = _value_of(i, c_new, ids[i, j], values[i, j])
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
