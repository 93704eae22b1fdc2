"""The listener of the asynchronous consensus: what an ACBBA message carries and how a receiver processes one.

Johnson §4.1.1 (Fig. 4-1, extraction line 763): each agent runs a Listener and a BundleBuilder; the listener
receives every message, deconflicts it at once ("This consensus module is run continuously so the algorithm is able to
immediately assess the relevance of incoming information", line 765) and sends what is relevant to two places, the
bundle-building buffer and the rebroadcast buffer. Here:

* a ``Message`` is one broadcast: the sender's *current* records of the tasks in its outgoing buffer when its build
  finished (the rebroadcast buffer holds task ids, so newer information prunes older, line 769). For a single-agent
  task the record is (z_kj, y_kj, t_kj); for a multi-agent task it is the column X_k[·][j] with each entry's time;
* ``listen`` processes one message at each of R distinct receivers in one vectorised call (receivers never read
  each other's tables, as in ``consensus.exchange``): single-agent tasks through the ACBBA table
  (``acbba_table.decide``/``apply``, Johnson Table 4.1), multi-agent tasks through CBGA's two-pass merge with
  per-entry times (``group_merge.merge_stamped``; not in the sources: our extension, docs/decisions.md). It returns
  which tasks are relevant, i.e. go to both buffers: a table action other than leave & no-rebroadcast (line 828),
  and for a column, a change, or a reply that would change the sender's column (the receiver knows better).

Accounting: a record is 4 data items (task, agent, bid, time): one per single-agent task, one per timed entry of a
column (withdrawn entries travel too, with their time, so releases propagate).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from taskalloc_env import acbba_table
from taskalloc_env.cbba_table import NONE
from taskalloc_env.config import TaskAllocConfig
from taskalloc_env.group_merge import merge_stamped
from taskalloc_env.groups import Equipment
from taskalloc_env.knowledge import LocalKnowledge
from taskalloc_env.stamps import NEVER


@dataclasses.dataclass
class Times:
    """Every agent's bid times: t_ij per single-agent task (Johnson §4.1.2, line 822) and one time per entry
    X_i[m][j] of a multi-agent column (our extension); packed ``stamps``, ``NEVER`` before anything is known.

    ``entry`` stays dense, unlike the groups (``group_table``): a withdrawn or displaced entry keeps its time with a
    zero bid, so that the withdrawal propagates and is not undone by an older record, so a column's timed entries
    are every agent that ever joined or left the group, which L_j does not bound."""

    task: np.ndarray        # (N, M)
    entry: np.ndarray       # (N, N, M)

    @classmethod
    def empty(cls, n_agents: int, n_tasks: int) -> Times:
        return cls(np.full((n_agents, n_tasks), NEVER, dtype=np.int64),
                   np.full((n_agents, n_agents, n_tasks), NEVER, dtype=np.int64))


@dataclasses.dataclass(frozen=True)
class Message:
    """One broadcast of ``sender`` at tick ``sent``: its records of the ``tasks`` of its outgoing buffer."""

    sender: int
    sent: int
    tasks: np.ndarray           # (M,) bool: the tasks the message carries
    winner: np.ndarray          # (M,) z_kj
    bid: np.ndarray             # (M,) y_kj
    time: np.ndarray            # (M,) t_kj
    columns: np.ndarray         # (N, M) X_k[m][j], the sender's table as a dense matrix
    entry_times: np.ndarray     # (N, M)
    known: np.ndarray           # (N,) the agents the sender has discovered (thesis §4.2.2, Table 4.5)
    data_items: int


def compose(kn: LocalKnowledge, times: Times, sender: int, sent: int, tasks: np.ndarray) -> Message:
    """The message of ``sender`` flushing its outgoing buffer ``tasks`` (M,) at tick ``sent``."""
    single = kn.single
    columns = kn.groups.dense(sender)
    entry_times = times.entry[sender].copy()
    items = 4 * int((tasks & single).sum() + ((entry_times != NEVER) & (tasks & ~single)[None, :]).sum())
    winner = np.where(single, kn.groups.members[sender, :, 0], NONE)
    bid = np.where(single, kn.groups.bids[sender, :, 0], 0.0)
    return Message(sender, sent, tasks.copy(), winner, bid, times.task[sender].copy(), columns, entry_times,
                   kn.known[sender].copy(), items)


def listen(kn: LocalKnowledge, times: Times, receivers: np.ndarray, messages: list[Message], now: int,
           cfg: TaskAllocConfig, required_agents: np.ndarray, equipment: Equipment) -> np.ndarray:
    """Process ``messages[r]`` at ``receivers[r]`` (all distinct) at tick ``now``; returns the (R, M) relevant tasks."""
    m = len(kn.single)
    carried = np.stack([msg.tasks for msg in messages])
    senders = np.array([msg.sender for msg in messages], dtype=np.int64)
    relevant = np.zeros((len(receivers), m), dtype=bool)
    single = kn.single
    if (carried & single[None, :]).any():
        relevant[:, single] = _single_tasks(kn, times, receivers, senders, messages, carried, now, cfg)
    multi = ~single
    if (carried & multi[None, :]).any():
        relevant[:, multi] = _group_tasks(kn, times, receivers, senders, messages, carried, required_agents,
                                          equipment)
    kn.known[receivers] |= np.stack([msg.known for msg in messages])
    kn.known[receivers, senders] = True
    kn.timestamps[receivers, senders] = now       # the last tick i heard k directly (the member_silence feature)
    return relevant


def _single_tasks(kn: LocalKnowledge, times: Times, receivers: np.ndarray, senders: np.ndarray,
                  messages: list[Message], carried: np.ndarray, now: int, cfg: TaskAllocConfig) -> np.ndarray:
    """Johnson Table 4.1 on the carried single-agent tasks; writes the receivers' records, returns relevance."""
    idx = np.flatnonzero(kn.single)
    carried = carried[:, idx]
    z_i = kn.groups.members[receivers[:, None], idx[None, :], 0]
    y_i = kn.groups.bids[receivers[:, None], idx[None, :], 0]
    t_i = times.task[receivers][:, idx]
    z_k = np.stack([msg.winner[idx] for msg in messages])
    y_k = np.stack([msg.bid[idx] for msg in messages])
    t_k = np.stack([msg.time[idx] for msg in messages])
    action, _ = acbba_table.decide(receivers, senders, z_k, y_k, t_k, z_i, y_i, t_i, row11=cfg.acbba_row11,
                                   row15=cfg.acbba_row15, row20_guard=cfg.acbba_row20_guard,
                                   row28_guard=cfg.acbba_row28_guard, ties=cfg.acbba_ties,
                                   equal_bids=cfg.acbba_equal_bids)
    z, y, t, rebroadcast = acbba_table.apply(action, receivers, now, z_i, y_i, t_i, z_k, y_k, t_k,
                                             cfg.acbba_time_refresh, cfg.acbba_outbid_time)
    moved = carried & ((z != z_i) | (y != y_i))
    r, j = np.nonzero(moved)
    kn.set_single_columns(receivers[r], idx[j], z[r, j], y[r, j])
    times.task[receivers[:, None], idx[None, :]] = np.where(carried, t, t_i)
    return carried & rebroadcast


def _group_tasks(kn: LocalKnowledge, times: Times, receivers: np.ndarray, senders: np.ndarray,
                 messages: list[Message], carried: np.ndarray, required_agents: np.ndarray,
                 equipment: Equipment) -> np.ndarray:
    """The stamped two-pass merge on the carried multi-agent columns; relevant: the column changed, or the
    receiver's column would change the sender's (it answers with its own, like Table 4.1's leave & rebroadcast)."""
    idx = np.flatnonzero(~kn.single)
    eq = equipment.subset(idx)
    needed = required_agents[idx]
    carried = carried[:, idx]
    block = np.ix_(receivers, np.arange(times.entry.shape[1]), idx)
    bids_i, t_i = kn.groups.columns(receivers, idx), times.entry[block]
    bids_k = np.stack([msg.columns[:, idx] for msg in messages])
    t_k = np.stack([msg.entry_times[:, idx] for msg in messages])
    merged, merged_t = merge_stamped(bids_i, t_i, bids_k, t_k, receivers, needed, eq)
    keep = ~carried[:, None, :]
    merged = np.where(keep, bids_i, merged)
    merged_t = np.where(keep, t_i, merged_t)
    changed = ((merged != bids_i) | (merged_t != t_i)).any(axis=1)
    reply, reply_t = merge_stamped(bids_k, t_k, merged, merged_t, senders, needed, eq)
    informative = ((reply != bids_k) | (reply_t != t_k)).any(axis=1)
    kn.groups.set_columns(receivers, idx, merged)
    times.entry[block] = merged_t
    return carried & (changed | informative)
