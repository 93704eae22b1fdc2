"""The group table: every agent's winning bids X_i[k][j], kept as the members of each task's group (thesis §4.2.1).

Thesis chapter 4 stores one bid matrix per agent, X_i[k][j] > 0 ⇔ agent i believes agent k is in task j's group
with bid X_i[k][j] (eqs. (4.2)–(4.3)). A column (i, ·, j) never holds more than L_j positive entries: a newcomer
joins only a group with room (n_j < L_j, (3.13)) or in place of the member it displaces (``groups.admit``, which the
bid view and the merge apply: ``group_merge.two_pass`` and its compiled mirror ``kernels.merge``), and a bid
displaces that member before it joins (``Protocol.bid``). So the table keeps, per holder i and task j,
W = max_j L_j *member slots* (at most N): the member ids in increasing order and their bids, the empty slots last
(id ``EMPTY``, bid 0). Memory grows like N·M·L instead of the N·N·M of a dense (holder, agent, task) array; a write
that would exceed L_j raises ``GroupOverflow`` instead of growing a column. A single-agent task's winner z_ij is
slot 0 of its column (thesis Table 3.1's z/y pair).

The layout is canonical (sorted members, cleared empty slots), so two tables are equal exactly when the dense
matrices they stand for are; the compiled merge (``kernels.merge.exchange_all``) writes it in place.
"""

from __future__ import annotations

import bisect
import dataclasses

import numpy as np

from taskalloc_env import kernels
from taskalloc_env.kernels.table import FULL, joined_members, set_member

EMPTY = -1                      # an empty member slot (equal to ``cbba_table.NONE``: slot 0 is the winner)


class GroupOverflow(ValueError):
    """A write would give a task's group more than L_j members in one table."""


@dataclasses.dataclass(eq=False)
class GroupTable:
    """The groups of every holder's table: (holder, task, slot) arrays of W = min(max_j L_j, N) member slots."""

    members: np.ndarray         # (N, M, W) member ids k, increasing; EMPTY after the last
    bids: np.ndarray            # (N, M, W) X_i[k][j] of each member; 0 in empty slots
    count: np.ndarray           # (N, M) n_j = #{k : X_i[k][j] > 0} (4.3)
    own: np.ndarray             # (N, M) X_i[i][j], the holder's own bids, kept with every write (read at every step)
    capacity: np.ndarray        # (M,) L_j
    n_agents: int

    @classmethod
    def empty(cls, n_holders: int, n_agents: int, capacity: np.ndarray) -> GroupTable:
        capacity = np.asarray(capacity, dtype=np.int64)
        m = len(capacity)
        width = max(min(int(capacity.max(initial=1)), n_agents), 1)        # a group has at most N members
        return cls(np.full((n_holders, m, width), EMPTY, dtype=np.int64), np.zeros((n_holders, m, width)),
                   np.zeros((n_holders, m), dtype=np.int64), np.zeros((n_holders, m)), capacity.copy(), n_agents)

    def copy(self) -> GroupTable:
        """A snapshot: the arrays copied (N·M·W members and bids, N·M counts and own bids), the capacities shared."""
        return GroupTable(self.members.copy(), self.bids.copy(), self.count.copy(), self.own.copy(), self.capacity,
                          self.n_agents)

    def __eq__(self, other: object) -> bool:
        """The same groups with the same bids in every table (the dense matrices are equal)."""
        if not isinstance(other, GroupTable):
            return NotImplemented
        return (np.array_equal(self.count, other.count) and np.array_equal(self.members, other.members)
                and np.array_equal(self.bids, other.bids))

    __hash__ = None                                       # type: ignore[assignment]  # mutable

    def same_table(self, i: int | np.ndarray, h: int | np.ndarray) -> bool:
        """Holders i and h hold the same table (X_i = X_h); with arrays of holders, every pair (i[q], h[q]) does."""
        return (np.array_equal(self.count[i], self.count[h]) and np.array_equal(self.members[i], self.members[h])
                and np.array_equal(self.bids[i], self.bids[h]))

    # -- reads -------------------------------------------------------------------------------------------------
    def bid(self, i: int, k: int, j: int) -> float:
        """X_i[k][j] (0 when k is no member of j's group in i's table)."""
        at = self._slot(i, k, j)
        return float(self.bids[i, j, at]) if at >= 0 else 0.0

    def member_counts(self) -> np.ndarray:
        """(N, M) n_j in every table (4.3)."""
        return self.count.copy()

    def own_bids(self) -> np.ndarray:
        """(N, M) X_i[i][j]: each holder's own bids."""
        return self.own.copy()

    def lists(self, agent: int) -> np.ndarray:
        """(N, M) the holders that list ``agent`` in task j's group."""
        return (self.members == agent).any(axis=2)

    def listing(self, agents: np.ndarray, tasks: np.ndarray) -> np.ndarray:
        """(N, Q) the holders that list ``agents[q]`` in the group of ``tasks[q]``."""
        return (self.members[:, tasks, :] == np.asarray(agents)[None, :, None]).any(axis=2)

    def listed(self) -> np.ndarray:
        """(N, N) holder i lists agent k in some group."""
        out = np.zeros((len(self.members), self.n_agents), dtype=bool)
        i, j, s = np.nonzero(self.members >= 0)
        out[i, self.members[i, j, s]] = True
        return out

    def joined(self, before: GroupTable) -> np.ndarray:
        """(N, M) a member of j's group in i's table that ``before`` did not list; compiled
        (``kernels.table.joined_members``) when numba is there, else ``joined_reference``."""
        if kernels.COMPILED:
            return joined_members(self.members, before.members)
        return self.joined_reference(before)

    def joined_reference(self, before: GroupTable) -> np.ndarray:
        """``joined`` in numpy (the reference of ``kernels.table.joined_members``)."""
        was = np.zeros(self.members.shape, dtype=bool)                                       # (N, M, W)
        for b in range(before.members.shape[2]):
            was |= self.members == before.members[:, :, b, None]
        return ((self.members >= 0) & ~was).any(axis=2)

    def changed(self, before: GroupTable) -> np.ndarray:
        """(N, M) column j of i's table differs from ``before``'s (a member or a bid)."""
        return ((self.members != before.members) | (self.bids != before.bids)).any(axis=2)

    def dense(self, i: int) -> np.ndarray:
        """(N, M) holder i's matrix X_i[k][j] (tests and debugging)."""
        return self.columns(np.array([i]), np.arange(self.members.shape[1]))[0]

    def columns(self, holders: np.ndarray, tasks: np.ndarray) -> np.ndarray:
        """(R, N, T) dense columns X_h[·][j] of ``holders`` × ``tasks`` (the numpy references' blocks)."""
        ids = self.members[holders[:, None], tasks[None, :]]                 # (R, T, W)
        out = np.zeros((len(holders), self.n_agents, len(tasks)))
        r, t, s = np.nonzero(ids >= 0)
        out[r, ids[r, t, s], t] = self.bids[holders[r], tasks[t], s]
        return out

    # -- writes ------------------------------------------------------------------------------------------------
    def set(self, i: int, k: int, j: int, value: float) -> None:
        """X_i[k][j] = value: k joins (or re-bids in) j's group if value > 0, leaves it otherwise; compiled
        (``kernels.table.set_member``) when numba is there, else ``set_reference``."""
        if not kernels.COMPILED:
            self.set_reference(i, k, j, value)
        elif set_member(self.members, self.bids, self.count, self.own, self.capacity, i, k, j, float(value)) == FULL:
            raise self._overflow(i, k, j, int(self.count[i, j]))

    def set_reference(self, i: int, k: int, j: int, value: float) -> None:
        """``set`` in Python (the reference of ``kernels.table.set_member``)."""
        n = int(self.count[i, j])
        if self.capacity[j] == 1:           # a single-agent column: slot 0 only, no order to keep
            present = n == 1 and self.members[i, j, 0] == k
            if value > 0:
                if not present and n:
                    raise self._overflow(i, k, j, n)
                self.members[i, j, 0], self.bids[i, j, 0], self.count[i, j] = k, value, 1
            elif present:
                self.members[i, j, 0], self.bids[i, j, 0], self.count[i, j] = EMPTY, 0.0, 0
            else:
                return
        elif not self._set_member(i, k, j, value, n):
            return
        if k == i:
            self.own[i, j] = value if value > 0 else 0.0

    def _set_member(self, i: int, k: int, j: int, value: float, n: int) -> bool:
        """``set`` on a column of L_j > 1 with ``n`` members, kept in increasing id order; whether it changed."""
        members, bids = self.members[i, j], self.bids[i, j]
        ids = members.tolist()
        at = bisect.bisect_left(ids, k, 0, n)
        present = at < n and ids[at] == k
        if value > 0:
            if not present:
                if n >= self.capacity[j]:
                    raise self._overflow(i, k, j, n)
                if at < n:
                    members[at + 1: n + 1] = members[at: n]
                    bids[at + 1: n + 1] = bids[at: n]
                members[at] = k
                self.count[i, j] = n + 1
            bids[at] = value
        elif present:
            if at < n - 1:
                members[at: n - 1] = members[at + 1: n]
                bids[at: n - 1] = bids[at + 1: n]
            members[n - 1], bids[n - 1] = EMPTY, 0.0
            self.count[i, j] = n - 1
        else:
            return False
        return True

    def _overflow(self, i: int, k: int, j: int, n: int) -> GroupOverflow:
        return GroupOverflow(f"agent {k} would be member {n + 1} of task {j}'s group in agent {i}'s table "
                             f"(L_j = {self.capacity[j]})")

    def set_winners(self, holders: np.ndarray, tasks: np.ndarray, winner: np.ndarray, bid: np.ndarray) -> None:
        """Overwrite single-agent columns (holder, task) with (winner, bid) pairs in slot 0 (EMPTY clears)."""
        has = winner != EMPTY
        self.members[holders, tasks, 0] = winner
        self.bids[holders, tasks, 0] = np.where(has, bid, 0.0)
        self.count[holders, tasks] = has
        self.own[holders, tasks] = np.where(winner == holders, self.bids[holders, tasks, 0], 0.0)

    def set_columns(self, holders: np.ndarray, tasks: np.ndarray, block: np.ndarray) -> None:
        """Overwrite the columns ``holders`` × ``tasks`` with the dense (R, N, T) ``block`` (its positive entries)."""
        present = block.transpose(0, 2, 1) > 0                               # (R, T, N)
        count = present.sum(axis=2)
        over = count > self.capacity[tasks][None, :]
        if over.any():
            r, t = np.argwhere(over)[0]
            raise GroupOverflow(f"task {tasks[t]}'s group would have {count[r, t]} members in agent "
                                f"{holders[r]}'s table (L_j = {self.capacity[tasks[t]]})")
        r, t, k = np.nonzero(present)                   # C order: members of each (r, t) in increasing id
        flat = count.ravel()
        slot = np.arange(len(r)) - np.repeat(np.cumsum(flat) - flat, flat)
        members = np.full((*count.shape, self.members.shape[2]), EMPTY, dtype=np.int64)
        bids = np.zeros(members.shape)
        members[r, t, slot] = k
        bids[r, t, slot] = block[r, k, t]
        where = np.ix_(holders, tasks)
        self.members[where] = members
        self.bids[where] = bids
        self.count[where] = count
        own = block[np.arange(len(holders))[:, None], holders[:, None], np.arange(len(tasks))[None, :]]
        self.own[where] = np.where(own > 0, own, 0.0)

    def _slot(self, i: int, k: int, j: int) -> int:
        """The slot of member k in (i, j), or −1."""
        n = int(self.count[i, j])
        at = bisect.bisect_left(self.members[i, j, :n].tolist(), k)
        return at if at < n and self.members[i, j, at] == k else -1
