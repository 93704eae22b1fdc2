"""Group rules of multi-agent tasks, in one place: equipment coverage and admission of a newcomer to a group.

A *group* is the set of agents holding a positive bid on task j in some table (a column j of X_i). Every rule that
asks whether a group is complete, whether an agent may join it, or whom it displaces is here, and the bid mask
(``bidding.bid_view``), the consensus merge (``group_merge.merge``) and the centralised greedy (``policies``'
SGAMA) all call it, so the mask and the consensus cannot drift apart.

Equipment (thesis §3.1.3, eq. (3.5)): agent i carries the set ae_i, task j requires te_j, held here as a multiset
(counts per item, our choice: the thesis's experiments ask for "two agents of type A", §3.3.2); te_j = ∅ lets any
agent join. A group *covers* te_j when its members' items include te_j as a multiset ((3.5), read with x_ij = 1).

Admission of a newcomer k with bid b to a column (thesis Alg 5 l. 8–20 and eqs. (3.12)–(3.14) in §3.2.2; the
equipment rule and (3.15) in §3.2.3; article eq. (9)):

* *room*: fewer than L_j members ((3.13), Alg 5 l. 10), and k's equipment fills an item of te_j the members leave
  unmet, or te_j = ∅ (thesis §3.2.3: "the new assignment must contribute to the correct equipment list");
* otherwise k may displace the (bid, id)-lowest member that carries an item of te_j that k carries too (any member
  when te_j = ∅; (3.15): ae_n = ae_m), if (b, k) outbids that member's (bid, id) (``cbba_table.outbids``: the
  higher id wins a tie, thesis §3.2.3).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from taskalloc_env.cbba_table import NONE, outbids


class Equipment:
    """Equipment arrays of one scenario: ae_i (N, E) as a bool matrix, te_j (M, E) as counts."""

    def __init__(self, agent_equipment: np.ndarray, task_equipment: np.ndarray) -> None:
        self.agent = agent_equipment.astype(bool)                 # (N, E) ae_i
        self.required = task_equipment.astype(np.int64)           # (M, E) te_j as counts
        self.restricted = self.required.any(axis=1)               # (M,) te_j ≠ ∅
        self.any = bool(self.restricted.any())

    def subset(self, tasks: np.ndarray) -> Equipment:
        """The same agents with the requirements of ``tasks`` only."""
        return Equipment(self.agent, self.required[tasks])

    def items(self, members: np.ndarray) -> np.ndarray:
        """(…, M, E) items the members carry per task, from a (…, N, M) member matrix (bool or 0/1)."""
        return np.einsum("...nm,ne->...me", members.astype(np.int64), self.agent.astype(np.int64))

    def covers(self, members: np.ndarray) -> np.ndarray:
        """(…, M): the members' items include te_j as a multiset, (3.5)."""
        if not self.any:
            return np.ones(members.shape[:-2] + members.shape[-1:], dtype=bool)
        return np.all(self.items(members) >= self.required, axis=-1)

    def slot_open(self, members: np.ndarray, newcomer: np.ndarray) -> np.ndarray:
        """(R, M): the newcomer's equipment meets an item of te_j that the (R, N, M) members leave unmet."""
        if not self.any:
            return np.ones(newcomer.shape, dtype=bool)
        unmet = self.required > self.items(members)                               # (R, M, E)
        fills = np.any(unmet & self.agent[newcomer], axis=2)
        return fills | ~self.restricted[None, :]

    def replaceable(self, members: np.ndarray, newcomer: np.ndarray) -> np.ndarray:
        """(R, N, M): members the newcomer may displace: any if te_j = ∅, else those sharing an item of te_j."""
        if not self.any:
            return members
        needed = self.agent[newcomer] & (self.required > 0)[None, :, :]               # (R, M, E)
        same = np.einsum("ne,rme->rnm", self.agent.astype(np.int64), needed.astype(np.int64)) > 0
        return members & (same | ~self.restricted[None, None, :])


@dataclasses.dataclass(frozen=True)
class Admission:
    """What a newcomer's bid does to a group, per (table, task): all (R, M)."""

    room: np.ndarray            # a free slot the newcomer's equipment fills
    displaced: np.ndarray       # the member it displaces, or NONE
    displaced_bid: np.ndarray   # that member's bid (0 if none)

    @property
    def accepted(self) -> np.ndarray:
        """The newcomer joins: there is room, or it displaces a member."""
        return self.room | (self.displaced != NONE)


def admit(columns: np.ndarray, newcomer: np.ndarray, bid: np.ndarray, required_agents: np.ndarray,
          equipment: Equipment, strict: bool = False) -> Admission:
    """Admission of ``newcomer`` (R, M) bidding ``bid`` (R, M) to the groups of ``columns`` (R, N, M) bids.

    ``required_agents`` is L_j (M,). The newcomer should not be a member already (callers exclude that case).
    ``strict``: displacing needs a strictly higher bid (the bundle phase's ">" of Alg 5 l. 12/18, option
    ``outbid_ties="strict"``); otherwise an equal bid from a higher id displaces too (the consensus order).
    """
    r_count, _, m = columns.shape
    members = columns > 0
    room = (members.sum(axis=1) < required_agents[None, :]) & equipment.slot_open(members, newcomer)
    victims = equipment.replaceable(members, newcomer)
    lowest = np.argmin(np.where(victims, columns, np.inf), axis=1)                  # (bid, id)-lowest
    low_bid = columns[np.arange(r_count)[:, None], lowest, np.arange(m)[None, :]]
    better = bid > low_bid if strict else outbids(bid, newcomer, low_bid, lowest)
    beats = ~room & victims.any(axis=1) & better
    return Admission(room=room, displaced=np.where(beats, lowest, NONE), displaced_bid=np.where(beats, low_bid, 0.0))
