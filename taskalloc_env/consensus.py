"""Phase 2: one synchronous round of message exchange and conflict resolution (thesis §3.2.3, Alg 6; §4.2.2).

Every agent sends its whole table to each neighbour (Alg 6 l. 1–2; whole tables are forwarded, so bids reach every
connected agent, thesis §3.2.1). Each message is a snapshot taken before any processing, so bids propagate one hop
per round and multi-hop over rounds; a receiver handles its inbox in ascending sender id (both our choices: the
thesis does not fix an order). Single-agent tasks go through the CBBA table (``cbba_table.decide``, Alg 6
l. 4–5), multi-agent tasks through the two-pass merge (``group_merge.merge``, Alg 6 l. 7–23). After each message
s_i[k] = T (Alg 6 l. 24); after the inbox, the timestamps of agents heard only through neighbours take the
freshest neighbour value (thesis eq. (2.4)).

The receivers at the same inbox position are processed in one vectorised call, which gives exactly the
sequential per-receiver semantics because receivers never read each other's tables within a round.

Accounting: one message = one (sender, receiver) pair = one communication step (thesis §3.3.2); a message holds
3·u + N_n data items (u = positive entries of the sender's table, one [task, agent, bid] triple each, plus the
timestamp vector; thesis §4.2.2 and §4.3).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from taskalloc_env.cbba_table import NONE, RESET, UPDATE, decide
from taskalloc_env.group_merge import merge
from taskalloc_env.groups import Equipment
from taskalloc_env.knowledge import LocalKnowledge
from taskalloc_env.network import CommGraph


@dataclasses.dataclass(frozen=True)
class Traffic:
    """What one round sent, in totals."""

    messages: int
    informative: int               # messages that changed the receiver's table
    data_items: int


def exchange(knowledge: LocalKnowledge, graph: CommGraph, now: int, required_agents: np.ndarray,
             equipment: Equipment, table: str = "canonical") -> Traffic:
    """Run one round of Phase 2 on every agent's table in place; returns the round's traffic."""
    kn = knowledge
    n = kn.bids.shape[0]
    agents = np.arange(n)
    kn.timestamps[agents, agents] = now
    sent_bids = kn.bids.copy()
    sent_winner = kn.winner.copy()
    sent_winning_bid = kn.winning_bid()
    sent_stamps = kn.timestamps.copy()
    # agents named in each message: the (agentID, time) pairs of the sender's timestamps cover every agent it knows,
    # the bid triples name only agents it knows; unknown ids are added on receipt (thesis §4.2.2, Table 4.5)
    sent_agents = kn.known.copy()
    single_idx = np.flatnonzero(kn.single)
    multi_idx = np.flatnonzero(~kn.single)
    multi_eq = equipment.subset(multi_idx)
    informative = np.zeros(n, dtype=np.int64)

    for receivers, senders in graph.inbox:
        s_i = kn.timestamps[receivers]
        s_k = sent_stamps[senders]
        changed = np.zeros(len(receivers), dtype=bool)
        if single_idx.size:
            z_i = kn.winner[receivers][:, single_idx]
            y_i = np.where(z_i == NONE, 0.0, kn.bids[receivers[:, None], np.maximum(z_i, 0), single_idx[None, :]])
            z_k = sent_winner[senders][:, single_idx]
            y_k = sent_winning_bid[senders][:, single_idx]
            action = decide(receivers, senders, z_i, y_i, z_k, y_k, s_i, s_k, table)
            new_z = np.where(action == UPDATE, z_k, np.where(action == RESET, NONE, z_i))
            new_y = np.where(action == UPDATE, y_k, np.where(action == RESET, 0.0, y_i))
            diff = (new_z != z_i) | (new_y != y_i)
            r, j = np.nonzero(diff)
            kn.set_single_columns(receivers[r], single_idx[j], new_z[r, j], new_y[r, j])
            changed |= diff.any(axis=1)
        if multi_idx.size:
            block = np.ix_(receivers, agents, multi_idx)
            before = kn.bids[block]
            after = merge(before, sent_bids[np.ix_(senders, agents, multi_idx)], receivers, senders, s_i, s_k,
                          required_agents[multi_idx], multi_eq)
            diff = (after != before).any(axis=(1, 2))
            if diff.any():
                kn.bids[block] = after
            changed |= diff
        kn.timestamps[receivers, senders] = now
        kn.known[receivers] |= sent_agents[senders]
        informative[receivers] += changed

    relayed = np.where(graph.adjacency[:, :, None], sent_stamps[None, :, :], -np.inf).max(axis=1)
    np.maximum(kn.timestamps, relayed, out=kn.timestamps)
    kn.timestamps[agents, agents] = now

    messages = int(graph.degree.sum())
    positive = (sent_bids > 0).sum(axis=(1, 2))
    items = int((graph.degree * (3 * positive + n)).sum())
    return Traffic(messages=messages, informative=int(informative.sum()), data_items=items)
