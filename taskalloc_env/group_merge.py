"""The two-pass merge of multi-agent task columns (spec cbga §4.3; thesis Alg 6 with the guards needed to run it).

``merge`` is pure: the receivers' bid columns and the senders' bid columns in, the receivers' updated columns
out. Arrays carry a leading receiver axis R (one message per receiver), an agent axis N and a task axis M, so a
round's messages at one position of every receiver's inbox are merged in one call.

Pass A refreshes what the receiver i already believes: for each member m ≠ i of column j, the sender's entry wins
if m is the sender or the sender heard from m more recently (it may be 0: m left or was displaced).
Pass B imports the sender's members that i does not hold, best (bid, id) first: a newcomer takes a free slot if
the group has room and its equipment fills an unmet need; otherwise it displaces the (bid, id)-lowest member with
the same equipment (3.15) if it outbids it. The displaced member may be i itself: that is how i learns it lost.
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.cbba_table import outbids


class Equipment:
    """Equipment arrays the merge and the outbid test share (spec cbga §1.4, §3.4)."""

    def __init__(self, agent_equipment: np.ndarray, task_equipment: np.ndarray) -> None:
        self.agent = agent_equipment.astype(bool)                 # (N, E) ae_i
        self.required = task_equipment.astype(np.int64)           # (M, E) te_j as counts
        self.restricted = self.required.any(axis=1)               # (M,) te_j ≠ ∅
        self.any = bool(self.restricted.any())

    def subset(self, tasks: np.ndarray) -> Equipment:
        return Equipment(self.agent, self.required[tasks])

    def slot_open(self, members: np.ndarray, newcomer: np.ndarray) -> np.ndarray:
        """(R, M): the newcomer's equipment meets an unmet item of te_j given the (R, N, M) members."""
        if not self.any:
            return np.ones(newcomer.shape, dtype=bool)
        have = np.einsum("rnm,ne->rme", members.astype(np.int64), self.agent.astype(np.int64))
        unmet = self.required[None, :, :] > have                   # (R, M, E)
        fills = np.any(unmet & self.agent[newcomer], axis=2)
        return fills | ~self.restricted[None, :]

    def replaceable(self, members: np.ndarray, newcomer: np.ndarray) -> np.ndarray:
        """(R, N, M): members n the newcomer may displace: any member if te_j = ∅, else ae_n ∩ ae_m ∩ te_j ≠ ∅."""
        if not self.any:
            return members
        needed = self.agent[newcomer] & (self.required > 0)[None, :, :]               # (R, M, E)
        same = np.einsum("ne,rme->rnm", self.agent.astype(np.int64), needed.astype(np.int64)) > 0
        return members & (same | ~self.restricted[None, None, :])


def merge(bids_i: np.ndarray, bids_k: np.ndarray, receiver: np.ndarray, sender: np.ndarray, s_i: np.ndarray,
          s_k: np.ndarray, required_agents: np.ndarray, equipment: Equipment) -> np.ndarray:
    """Merge sender columns ``bids_k`` (R, N, M) into receiver columns ``bids_i``; returns the new columns.

    ``s_i``/``s_k`` (R, N) are the timestamps before this message; ``required_agents`` is L_j per column.
    """
    r_count, n_agents, _ = bids_i.shape
    agents = np.arange(n_agents)
    trust = (agents[None, :] == sender[:, None]) | (s_k > s_i)
    trust &= agents[None, :] != receiver[:, None]                          # i is authoritative on its own row
    # Pass A
    out = np.where((bids_i > 0) & trust[:, :, None], bids_k, bids_i)
    # Pass B
    candidates = (bids_k > 0) & (out == 0) & trust[:, :, None]
    rows = np.arange(r_count)[:, None]
    cols = np.arange(bids_i.shape[2])[None, :]
    while candidates.any():
        active = candidates.any(axis=1)                                            # (R, M)
        keyed = np.where(candidates, bids_k, -np.inf)
        newcomer = n_agents - 1 - np.argmax(keyed[:, ::-1, :], axis=1)             # best bid, ties: higher id
        bid = bids_k[rows, newcomer, cols]
        members = out > 0
        room = (members.sum(axis=1) < required_agents[None, :]) & equipment.slot_open(members, newcomer)
        victims = equipment.replaceable(members, newcomer)
        lowest = np.argmin(np.where(victims, out, np.inf), axis=1)                  # (bid, id)-minimum
        low_bid = out[rows, lowest, cols]
        replace = ~room & victims.any(axis=1) & outbids(bid, newcomer, low_bid, lowest)
        take = active & (room | replace)
        evict = active & replace
        r_idx, j_idx = np.nonzero(evict)
        out[r_idx, lowest[r_idx, j_idx], j_idx] = 0.0
        r_idx, j_idx = np.nonzero(take)
        out[r_idx, newcomer[r_idx, j_idx], j_idx] = bid[r_idx, j_idx]
        r_idx, j_idx = np.nonzero(active)
        candidates[r_idx, newcomer[r_idx, j_idx], j_idx] = False
    return out
