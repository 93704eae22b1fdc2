"""Every agent's local knowledge: winning bids, timestamps, bundle, path, quit timers (thesis §3.2.1, §4.2, §5.2.2).

Storage follows thesis chapter 4 (§4.2.1, eqs. (4.2)–(4.3), Table 4.3): one bid matrix per agent, X_i[k][j] > 0
⇔ agent k holds bid X_i[k][j] on task j (the binary matrix of chapter 3 is implied), keyed by agent and task ids so
that a message carries only positive entries (thesis §4.2.2). All agents' matrices live in one ``GroupTable``
(``group_table``), stored sparsely: a column (i, ·, j) never holds more than L_j members (``groups.admit`` keeps
every group to L_j in the bundle phase and in the merge, and a bid displaces before it joins), so each holder keeps
at most W = max_j L_j member slots per task and memory grows like N·M·L, not N·N·M. ``known[i, k]``
records which agents i has discovered (its own id always; others on first contact or when a relayed triple names
them, thesis Table 4.5).

For single-agent tasks the winner z_ij is slot 0 of the column (``winner``, NONE for none), which is what the CBBA
table reads; every write goes through this class and ``GroupTable``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from taskalloc_env.cbba_table import NONE
from taskalloc_env.group_table import GroupTable

NEVER = -1


@dataclasses.dataclass
class LocalKnowledge:
    """Local tables of all N agents over M tasks; row i of every array belongs to agent i."""

    groups: GroupTable          # X_i[k][j] as the members of each group (N, M, W)
    timestamps: np.ndarray      # (N, N) s_i[k], in rounds
    known: np.ndarray           # (N, N) agents i has discovered
    bundles: list[list[int]]    # b_i, insertion order
    paths: list[list[int]]      # p_i, execution order
    assigned_at: np.ndarray     # (N, M) H_i[j] (thesis §5.2.2, (5.6))
    quit: np.ndarray            # (N, M) Q_i[j] (thesis §5.2.2, Alg 9)
    quit_blocked: np.ndarray    # (N, M) i quit j and no other agent has joined j since (quit_block="until_joined")
    single: np.ndarray          # (M,) L_j == 1

    @classmethod
    def empty(cls, n_agents: int, n_tasks: int, group_sizes: np.ndarray, know_everyone: bool) -> LocalKnowledge:
        """Empty tables for tasks of ``group_sizes`` L_j (M,)."""
        group_sizes = np.asarray(group_sizes, dtype=np.int64)
        return cls(
            groups=GroupTable.empty(n_agents, n_agents, group_sizes),
            timestamps=np.zeros((n_agents, n_agents)),
            known=np.ones((n_agents, n_agents), dtype=bool) if know_everyone else np.eye(n_agents, dtype=bool),
            bundles=[[] for _ in range(n_agents)],
            paths=[[] for _ in range(n_agents)],
            assigned_at=np.full((n_agents, n_tasks), NEVER, dtype=np.int64),
            quit=np.zeros((n_agents, n_tasks), dtype=bool),
            quit_blocked=np.zeros((n_agents, n_tasks), dtype=bool),
            single=group_sizes == 1,
        )

    # -- views -------------------------------------------------------------------------------------------------
    @property
    def winner(self) -> np.ndarray:
        """(N, M) z_ij: the member of each single-agent task's group (slot 0), NONE for none and for L_j > 1."""
        return np.where(self.single[None, :], self.groups.members[:, :, 0], NONE)

    def own_bids(self) -> np.ndarray:
        """(N, M) X_i[i][j]: each agent's own bids."""
        return self.groups.own_bids()

    def winning_bid(self) -> np.ndarray:
        """(N, M) y_ij: the bid of the winner of each single-agent task (0 for none and for L_j > 1)."""
        return np.where(self.single[None, :], self.groups.bids[:, :, 0], 0.0)

    def member_counts(self) -> np.ndarray:
        """(N, M) #{k : X_i[k][j] > 0} (4.3)."""
        return self.groups.member_counts()

    # -- writes ------------------------------------------------------------------------------------------------
    def set_bid(self, i: int, k: int, j: int, value: float) -> None:
        """X_i[k][j] = value (k leaves j's group when value is 0)."""
        self.groups.set(i, k, j, value)

    def set_single_columns(self, holders: np.ndarray, tasks: np.ndarray, new_winner: np.ndarray,
                           new_bid: np.ndarray) -> None:
        """Overwrite whole single-agent columns (holder, task) with (winner, bid) pairs (NONE clears)."""
        self.groups.set_winners(holders, tasks, new_winner, new_bid)

    def add_to_bundle(self, i: int, j: int, slot: int, bid: float, now: int, displaced: int = NONE) -> None:
        """b_i ⊕_end j, p_i ⊕_slot j, X_i[i][j] = c_ij, H_i[j] = T (Alg 5 lines 23–26, (5.6)); the member
        ``displaced`` (NONE: none) leaves j's group in i's table first (our choice: n_j ≤ L_j locally, Phase 2
        propagates the eviction)."""
        self.bundles[i].append(j)
        self.paths[i].insert(slot, j)
        if displaced != NONE:
            self.set_bid(i, displaced, j, 0.0)
        self.set_bid(i, i, j, bid)
        self.assigned_at[i, j] = now

    def release(self, i: int, lost: int, order: str) -> list[int]:
        """Drop ``lost`` and every task after it from b_i and p_i, zeroing i's own bids on them (thesis §2.2.4).

        ``order="bundle"`` releases what was added after ``lost``; ``order="path"`` what is scheduled after it.
        Returns the released tasks other than ``lost``.
        """
        sequence = self.bundles[i] if order == "bundle" else self.paths[i]
        cut = sequence.index(lost)
        dropped = sequence[cut:]
        gone = set(dropped)
        self.bundles[i] = [j for j in self.bundles[i] if j not in gone]
        self.paths[i] = [j for j in self.paths[i] if j not in gone]
        for j in dropped:
            self.set_bid(i, i, j, 0.0)
        return dropped[1:]
