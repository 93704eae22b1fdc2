"""Every agent's local knowledge: winning bids, timestamps, bundle, path, quit timers (thesis §3.2.1, §4.2, §5.2.2).

Storage follows thesis chapter 4 (§4.2.1, eqs. (4.2)–(4.3), Table 4.3): one bid matrix per agent, X_i[k][j] > 0
⇔ agent k holds bid X_i[k][j] on task j (the binary matrix of chapter 3 is implied). All agents' matrices live in
one array ``bids[i, k, j]`` indexed by agent and task id (our storage choice), so a message is keyed by ids and only
positive entries carry information (thesis §4.2.2). ``known[i, k]`` records which agents i has discovered (its own
id always; others on first contact or when a relayed triple names them, thesis Table 4.5).

For single-agent tasks ``winner[i, j]`` caches the one positive entry of column j (or NONE), which is what the CBBA
table reads; every write goes through this class so the cache and ``bids`` never disagree.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from taskalloc_env.cbba_table import NONE

NEVER = -1


@dataclasses.dataclass
class LocalKnowledge:
    """Local tables of all N agents over M tasks; row i of every array belongs to agent i."""

    bids: np.ndarray            # (N, N, M) X_i[k][j]
    winner: np.ndarray          # (N, M) single-agent tasks: the k with X_i[k][j] > 0, or NONE
    timestamps: np.ndarray      # (N, N) s_i[k], in rounds
    known: np.ndarray           # (N, N) agents i has discovered
    bundles: list[list[int]]    # b_i, insertion order
    paths: list[list[int]]      # p_i, execution order
    assigned_at: np.ndarray     # (N, M) H_i[j] (thesis §5.2.2, (5.6))
    quit: np.ndarray            # (N, M) Q_i[j] (thesis §5.2.2, Alg 9)
    quit_blocked: np.ndarray    # (N, M) i quit j and no other agent has joined j since (quit_block="until_joined")
    single: np.ndarray          # (M,) L_j == 1

    @classmethod
    def empty(cls, n_agents: int, n_tasks: int, single: np.ndarray, know_everyone: bool) -> LocalKnowledge:
        return cls(
            bids=np.zeros((n_agents, n_agents, n_tasks)),
            winner=np.full((n_agents, n_tasks), NONE, dtype=np.int64),
            timestamps=np.zeros((n_agents, n_agents)),
            known=np.ones((n_agents, n_agents), dtype=bool) if know_everyone else np.eye(n_agents, dtype=bool),
            bundles=[[] for _ in range(n_agents)],
            paths=[[] for _ in range(n_agents)],
            assigned_at=np.full((n_agents, n_tasks), NEVER, dtype=np.int64),
            quit=np.zeros((n_agents, n_tasks), dtype=bool),
            quit_blocked=np.zeros((n_agents, n_tasks), dtype=bool),
            single=single.copy(),
        )

    # -- views -------------------------------------------------------------------------------------------------
    def own_bids(self) -> np.ndarray:
        """(N, M) X_i[i][j]: each agent's own bids."""
        return np.diagonal(self.bids, axis1=0, axis2=1).T.copy()

    def winning_bid(self) -> np.ndarray:
        """(N, M) the bid of the cached winner of each single-agent task (0 for none)."""
        n, m = self.winner.shape
        return np.where(self.winner == NONE, 0.0,
                        self.bids[np.arange(n)[:, None], np.maximum(self.winner, 0), np.arange(m)[None, :]])

    def member_counts(self) -> np.ndarray:
        """(N, M) #{k : X_i[k][j] > 0} (4.3)."""
        return (self.bids > 0).sum(axis=1)

    # -- writes ------------------------------------------------------------------------------------------------
    def set_bid(self, i: int, k: int, j: int, value: float) -> None:
        """X_i[k][j] = value, keeping the single-agent winner cache."""
        self.bids[i, k, j] = value
        if self.single[j]:
            if value > 0:
                self.winner[i, j] = k
            elif self.winner[i, j] == k:
                self.winner[i, j] = NONE

    def set_single_columns(self, holders: np.ndarray, tasks: np.ndarray, new_winner: np.ndarray,
                           new_bid: np.ndarray) -> None:
        """Overwrite whole single-agent columns (holder, task) with (winner, bid) pairs (NONE clears)."""
        old = self.winner[holders, tasks]
        had = old != NONE
        self.bids[holders[had], old[had], tasks[had]] = 0.0
        has = new_winner != NONE
        self.bids[holders[has], new_winner[has], tasks[has]] = new_bid[has]
        self.winner[holders, tasks] = new_winner

    def add_to_bundle(self, i: int, j: int, slot: int, bid: float, now: int) -> None:
        """b_i ⊕_end j, p_i ⊕_slot j, X_i[i][j] = c_ij, H_i[j] = T (Alg 5 lines 23–26, (5.6))."""
        self.bundles[i].append(j)
        self.paths[i].insert(slot, j)
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
            if self.bids[i, i, j] > 0:
                self.set_bid(i, i, j, 0.0)
        return dropped[1:]
