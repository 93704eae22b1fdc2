"""Phase 2: message exchange and conflict resolution (thesis §3.2.3, Alg 6; §4.2.2).

Every live agent sends its whole table to each neighbour (Alg 6 l. 1–2; whole tables are forwarded, so bids reach
every connected agent, thesis §3.2.1). Each message is a ``Snapshot`` taken before any processing, so bids propagate
one hop per round and multi-hop over rounds. Which messages arrive, and when, is the ``network.Network``'s business;
``exchange`` processes what arrives: a receiver handles its messages in the order of ``network.Deliveries``
(ascending send round, then sender id — our choice: the thesis does not fix an order). Single-agent tasks go through
the CBBA table (``cbba_table.decide``, Alg 6 l. 4–5), multi-agent tasks through the two-pass merge
(``group_merge.merge``, Alg 6 l. 7–23). After each message
s_i[k] = T (Alg 6 l. 24); after the inbox, the timestamps of agents heard only through neighbours take the
freshest value among the messages received (thesis eq. (2.4)).

The receivers at the same inbox position are processed in one vectorised call, which gives exactly the
sequential per-receiver semantics because receivers never read each other's tables within a round.

Accounting: one message = one (sender, receiver) pair = one communication step (thesis §3.3.2); a message holds
3·u + N_n data items (u = positive entries of the sender's table, one [task, agent, bid] triple each, plus the
timestamp vector; thesis §4.2.2 and §4.3).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from taskalloc_env import kernels
from taskalloc_env.cbba_table import NONE, RESET, UPDATE, decide
from taskalloc_env.group_merge import merge
from taskalloc_env.group_table import GroupTable
from taskalloc_env.groups import Equipment
from taskalloc_env.kernels.merge import exchange_all
from taskalloc_env.knowledge import LocalKnowledge
from taskalloc_env.network import CommGraph, Deliveries


@dataclasses.dataclass(frozen=True)
class Snapshot:
    """Every agent's table as it was sent in one round (a message is its sender's row of each array)."""

    round: int
    groups: GroupTable          # the groups of every table, N·M·W (a single-agent task's winner and bid: slot 0)
    stamps: np.ndarray          # (N, N)
    known: np.ndarray           # (N, N): the agents each message names (its timestamps cover every agent it knows,
                                #         its triples name only known agents; thesis §4.2.2, Table 4.5)
    data_items: np.ndarray      # (N,) items of each message: 3 per positive table entry + N_n timestamps (thesis §4.3)


def snapshot(knowledge: LocalKnowledge, now: int) -> Snapshot:
    """The messages of round ``now``: each agent stamps itself with T, then copies its table."""
    kn = knowledge
    n = len(kn.timestamps)
    np.fill_diagonal(kn.timestamps, now)
    groups = kn.groups.copy()
    return Snapshot(now, groups, kn.timestamps.copy(), kn.known.copy(), 3 * groups.count.sum(axis=1) + n)


@dataclasses.dataclass(frozen=True)
class Traffic:
    """What one round delivered, in totals."""

    messages: int
    informative: int               # messages that changed the receiver's table
    data_items: int


def exchange(knowledge: LocalKnowledge, deliveries: Deliveries, snapshots: dict[int, Snapshot], now: int,
             required_agents: np.ndarray, equipment: Equipment, table: str = "canonical") -> Traffic:
    """Process the messages of ``deliveries`` (sent in the rounds of ``snapshots``) on the receivers' tables: in
    compiled loops (``kernels.exchange_all``) when numba is there, else with ``exchange_reference``."""
    if not kernels.COMPILED:
        return exchange_reference(knowledge, deliveries, snapshots, now, required_agents, equipment, table)
    if not len(deliveries):             # nothing arrives; every agent still stamps itself with T
        np.fill_diagonal(knowledge.timestamps, now)
        return Traffic(messages=0, informative=0, data_items=0)
    kn = knowledge
    first, last = int(deliveries.sent.min()), int(deliveries.sent.max())
    if first == last:                                   # one send round (always on links without delay)
        sent, slot = np.array([first]), np.zeros(len(deliveries), dtype=np.int64)
    else:
        sent = np.unique(deliveries.sent)               # the send rounds, ascending
        slot = np.searchsorted(sent, deliveries.sent)
    stack = [snapshots[r] for r in sent.tolist()]

    def stacked(arrays: list[np.ndarray]) -> np.ndarray:
        return arrays[0][None] if len(arrays) == 1 else np.array(arrays)

    g = kn.groups
    informative = exchange_all(
        g.count, g.members, g.bids, g.own, kn.timestamps, kn.known, stacked([snap.groups.count for snap in stack]),
        stacked([snap.groups.members for snap in stack]), stacked([snap.groups.bids for snap in stack]),
        stacked([snap.stamps for snap in stack]), stacked([snap.known for snap in stack]), deliveries.receiver,
        deliveries.sender, slot, float(now), kn.single, required_agents, equipment.restricted, equipment.required,
        equipment.agent, table == "canonical")
    items = int(stacked([snap.data_items for snap in stack])[slot, deliveries.sender].sum())
    return Traffic(messages=len(deliveries), informative=int(informative), data_items=items)


def exchange_reference(knowledge: LocalKnowledge, deliveries: Deliveries, snapshots: dict[int, Snapshot], now: int,
                       required_agents: np.ndarray, equipment: Equipment, table: str = "canonical") -> Traffic:
    """``exchange`` in numpy, vectorised over the receivers at each inbox position (the reference).

    The multi-agent columns are merged as dense (receivers, agents, tasks) blocks of the receivers at one inbox
    position, built from the group tables and written back (``GroupTable.columns``/``set_columns``); no array
    covers the whole team's N·N·M.
    """
    kn = knowledge
    n = len(kn.timestamps)
    agents = np.arange(n)
    single_idx = np.flatnonzero(kn.single)
    multi_idx = np.flatnonzero(~kn.single)
    multi_eq = equipment.subset(multi_idx)
    informative = 0
    relayed = np.full((n, n), -np.inf)
    items = 0
    for position in deliveries.positions():
        for sent in np.unique(deliveries.sent[position]):
            pick = position[deliveries.sent[position] == sent]
            receivers, senders, snap = deliveries.receiver[pick], deliveries.sender[pick], snapshots[int(sent)]
            informative += int(_process(kn, receivers, senders, snap, now, required_agents, single_idx, multi_idx,
                                        multi_eq, table).sum())
            np.maximum.at(relayed, receivers, snap.stamps[senders])
            items += int(snap.data_items[senders].sum())
    np.maximum(kn.timestamps, relayed, out=kn.timestamps)
    kn.timestamps[agents, agents] = now
    return Traffic(messages=len(deliveries), informative=informative, data_items=items)


def _process(kn: LocalKnowledge, receivers: np.ndarray, senders: np.ndarray, snap: Snapshot, now: int,
             required_agents: np.ndarray, single_idx: np.ndarray, multi_idx: np.ndarray, multi_eq: Equipment,
             table: str) -> np.ndarray:
    """One message to each of ``receivers`` (all distinct), vectorised; returns which receivers' tables changed."""
    s_i = kn.timestamps[receivers]
    s_k = snap.stamps[senders]
    changed = np.zeros(len(receivers), dtype=bool)
    if single_idx.size:
        z_i = kn.groups.members[receivers[:, None], single_idx[None, :], 0]
        y_i = kn.groups.bids[receivers[:, None], single_idx[None, :], 0]
        z_k = snap.groups.members[senders[:, None], single_idx[None, :], 0]
        y_k = snap.groups.bids[senders[:, None], single_idx[None, :], 0]
        action = decide(receivers, senders, z_i, y_i, z_k, y_k, s_i, s_k, table)
        new_z = np.where(action == UPDATE, z_k, np.where(action == RESET, NONE, z_i))
        new_y = np.where(action == UPDATE, y_k, np.where(action == RESET, 0.0, y_i))
        diff = (new_z != z_i) | (new_y != y_i)
        r, j = np.nonzero(diff)
        kn.set_single_columns(receivers[r], single_idx[j], new_z[r, j], new_y[r, j])
        changed |= diff.any(axis=1)
    if multi_idx.size:
        before = kn.groups.columns(receivers, multi_idx)
        after = merge(before, snap.groups.columns(senders, multi_idx), receivers, senders, s_i, s_k,
                      required_agents[multi_idx], multi_eq)
        diff = (after != before).any(axis=(1, 2))
        if diff.any():
            kn.groups.set_columns(receivers[diff], multi_idx, after[diff])
        changed |= diff
    kn.timestamps[receivers, senders] = now
    kn.known[receivers] |= snap.known[senders]
    return changed


def broadcast_round(knowledge: LocalKnowledge, graph: CommGraph, now: int, required_agents: np.ndarray,
                    equipment: Equipment, table: str = "canonical") -> Traffic:
    """One round over perfect links: every agent's snapshot reaches every neighbour at once (``Network``'s
    ``perfect`` case, written out for tests and worked examples)."""
    snap = snapshot(knowledge, now)
    sender, receiver = np.nonzero(graph.adjacency)
    return exchange(knowledge, Deliveries.of(receiver, sender, np.full(len(sender), now)), {now: snap}, now,
                    required_agents, equipment, table)
