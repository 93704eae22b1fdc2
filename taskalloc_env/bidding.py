"""Which bids each agent may place, read from its own local table (thesis §3.2.2, Alg 5 l. 7–21).

``bid_view`` computes, for every agent i and task j at once:

* the eligibility filters: equipment (te_j = ∅ or ae_i ∩ te_j ≠ ∅, thesis §3.1.3), prerequisites per
  ``prereq_mode`` ((3.6), article eq. (5); which reading is our choice), a feasible insertion (c_ij > 0, the window
  rule (3.7)), ``require_known_capacity``, ``quit_block``, j ∉ b_i, |b_i| < M_m (Alg 5 l. 6); bids failing them
  "will not be considered" (thesis §3.2.2);
* the outbid test h_ij (Alg 5 l. 8–20): for L_j = 1, (c_ij, i) ≻ (y_j, z_j) ((3.12), ties to the higher id); for
  L_j > 1, a free slot that i's equipment fills, or (c_ij, i) ≻ the (bid, id)-lowest same-equipment member
  ((3.13)–(3.15));
* what the bid would do to the group: the member it would displace, that member's bid, the group total
  Σ_k X_i[k][j] (4.2), so that the team value of (5.5) is group_total − displaced_bid + c_ij (``team_value=net``).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence

import numpy as np

from taskalloc_env import kernels
from taskalloc_env.cbba_table import NONE, outbids
from taskalloc_env.groups import Equipment, admit
from taskalloc_env.kernels.bids import PREREQ_MODES, bid_rows
from taskalloc_env.knowledge import LocalKnowledge
from taskalloc_env.scenario import Scenario


@dataclasses.dataclass(frozen=True)
class BidView:
    """Per (agent, task) arrays, all (N, M), describing the agents' tables as they are when the view is taken and
    until the protocol next changes them (``Protocol.view`` updates the arrays in place; copy what must outlive
    that)."""

    gain: np.ndarray            # c_ij (3.11), the agent's own value of the task
    bid: np.ndarray             # what a bid stores and shares: c_ij, or min(c_ij, earlier bundle bids) warped
    slot: np.ndarray            # n_ij, the best insertion slot
    outbid: np.ndarray          # h_ij
    eligible: np.ndarray        # every eligibility filter except the window (which ``gain`` > 0 encodes)
    equipment_match: np.ndarray
    prereqs_met: np.ndarray
    members: np.ndarray         # member count n_j in i's table
    group_total: np.ndarray     # C_j = Σ_k X_i[k][j]
    lowest_bid: np.ndarray      # the lowest member bid (0 if no member)
    displaced: np.ndarray       # the member a bid would displace, or NONE
    displaced_bid: np.ndarray   # that member's bid (0 if none)
    in_bundle: np.ndarray

    @functools.cached_property
    def can_bid(self) -> np.ndarray:
        """Valid bids: eligible, outbidding, with a positive marginal gain."""
        return self.eligible & self.outbid & (self.gain > 0)

    @property
    def team_value(self) -> np.ndarray:
        """Σ_k X_i[k][j] − (displaced bid) + c_ij: the group total after the bid (thesis §5.2.1, (5.5); ``net``)."""
        return self.group_total - self.displaced_bid + self.gain


def prerequisites_met(scenario: Scenario, mode: str, counts: np.ndarray,
                      complete: np.ndarray | None = None) -> np.ndarray:
    """(H, M) prerequisite filter per ``prereq_mode`` (thesis (3.6), article eq. (5)) from H tables' counts (H, M).

    ``complete`` (H, M), the groups that are full with their equipment covered, is needed for ``all_complete``.
    """
    prereqs = scenario.task_prereqs
    if not prereqs.any():
        return np.ones(counts.shape, dtype=bool)
    lacking = prereqs.astype(np.int64).T
    if mode == "all_have_bid":
        return (counts == 0).astype(np.int64) @ lacking == 0
    if mode == "all_complete":
        if complete is None:
            raise ValueError("prereq_mode all_complete needs the complete groups")
        return (~complete).astype(np.int64) @ lacking == 0
    has_prereqs = prereqs.any(axis=1)[None, :]
    return ((counts > 0).astype(np.int64) @ lacking > 0) | ~has_prereqs


def complete_groups(bids: np.ndarray, scenario: Scenario, equipment: Equipment) -> np.ndarray:
    """(H, M) column j of table h has L_j members whose equipment covers te_j."""
    members = bids > 0
    return (members.sum(axis=1) == scenario.task_agents[None, :]) & equipment.covers(members)


def known_capacity(knowledge: LocalKnowledge, scenario: Scenario, equipment: Equipment,
                   equipment_match: np.ndarray) -> np.ndarray:
    """(N, M) i knows at least L_j agents (itself included) that can jointly cover te_j.

    Our choice, after thesis §4.3: an agent without communication partners has "no way to make any valid
    assignments" to multi-agent tasks.
    """
    known = knowledge.known.astype(np.int64)
    enough = known @ equipment_match.astype(np.int64) >= scenario.task_agents[None, :]
    covered = equipment.covers(np.broadcast_to(knowledge.known[:, :, None], (*known.shape, scenario.n_tasks)))
    return (enough & covered) | ~scenario.multi_agent[None, :]


def bid_view(knowledge: LocalKnowledge, scenario: Scenario, equipment: Equipment, equipment_match: np.ndarray,
             gain: np.ndarray, slot: np.ndarray, *, prereq_mode: str, require_known_capacity: bool,
             max_bundle: int, fillable: np.ndarray, bid_warping: bool = False, outbid_ties: str = "strict") -> BidView:
    """The bidding situation of every agent, computed from its local table only (the numpy reference of
    ``refresh_rows``; it reads the multi-agent groups as one dense (N, N, M) block, ``GroupTable.columns``).

    ``fillable`` (M,) marks the tasks some team of the scenario can complete: every agent knows all agents'
    equipment (thesis §3.2.1), so the capacity filter applies with everyone known (our choice); with
    ``require_known_capacity`` the agents that i has discovered must suffice as well.
    """
    n, m = gain.shape
    agents = np.arange(n)
    counts = np.zeros((n, m), dtype=np.int64)
    group_total = np.zeros((n, m))
    lowest_bid = np.zeros((n, m))
    own = knowledge.own_bids()
    in_bundle = own > 0
    # warped bids (bid_warping): never above an earlier bid of the bundle, whose last bid is its lowest
    bid = np.minimum(gain, np.where(in_bundle, own, np.inf).min(axis=1)[:, None]) if bid_warping else gain
    strict = outbid_ties == "strict"
    outbid = np.zeros((n, m), dtype=bool)
    displaced = np.full((n, m), NONE, dtype=np.int64)
    displaced_bid = np.zeros((n, m))

    single = knowledge.single
    if single.any():            # one winner per column: slot 0 of the group
        winner = knowledge.winner[:, single]
        held = knowledge.winning_bid()[:, single]
        counts[:, single] = winner != NONE
        group_total[:, single] = held
        lowest_bid[:, single] = held
        better = bid[:, single] > held if strict else outbids(bid[:, single], agents[:, None], held, winner)
        outbid[:, single] = (winner == NONE) | better
        displaced[:, single] = winner
        displaced_bid[:, single] = held
    multi = ~single
    if multi.any():
        columns = knowledge.groups.columns(agents, np.flatnonzero(multi))        # the reference: dense blocks
        members = columns > 0
        counts[:, multi] = members.sum(axis=1)
        group_total[:, multi] = columns.sum(axis=1)
        lowest_bid[:, multi] = np.where(counts[:, multi] > 0, np.where(members, columns, np.inf).min(axis=1), 0.0)
        newcomer = np.broadcast_to(agents[:, None], (n, int(multi.sum())))
        admission = admit(columns, newcomer, bid[:, multi], scenario.task_agents[multi], equipment.subset(multi),
                          strict=strict)
        outbid[:, multi] = admission.accepted
        displaced[:, multi] = admission.displaced
        displaced_bid[:, multi] = admission.displaced_bid

    complete = (complete_groups(knowledge.groups.columns(agents, np.arange(m)), scenario, equipment)
                if prereq_mode == "all_complete" else None)
    prereqs_met = prerequisites_met(scenario, prereq_mode, counts, complete)
    eligible = equipment_match & prereqs_met & ~in_bundle & fillable[None, :]
    if require_known_capacity:
        eligible &= known_capacity(knowledge, scenario, equipment, equipment_match)
    eligible &= ~knowledge.quit_blocked
    bundle_sizes = np.array([len(b) for b in knowledge.bundles])
    eligible &= (bundle_sizes < max_bundle)[:, None]
    return BidView(gain=gain, bid=bid, slot=slot, outbid=outbid, eligible=eligible, equipment_match=equipment_match,
                   prereqs_met=prereqs_met, members=counts, group_total=group_total, lowest_bid=lowest_bid,
                   displaced=displaced, displaced_bid=displaced_bid, in_bundle=in_bundle)


ROW_FIELDS = ("bid", "outbid", "eligible", "prereqs_met", "members", "group_total", "lowest_bid", "displaced",
              "displaced_bid", "in_bundle")


@functools.lru_cache(maxsize=8)
def _everyone_known(n: int, m: int) -> np.ndarray:
    """The (N, M) capacity mask when every agent is known from the start (read-only, shared)."""
    known = np.ones((n, m), dtype=bool)
    known.setflags(write=False)
    return known


def refresh_rows(previous: BidView | None, rows: Sequence[int], knowledge: LocalKnowledge, scenario: Scenario,
                 equipment: Equipment, equipment_match: np.ndarray, gain: np.ndarray, slot: np.ndarray, *,
                 prereq_mode: str, require_known_capacity: bool, max_bundle: int, fillable: np.ndarray,
                 bid_warping: bool = False, outbid_ties: str = "strict") -> BidView:
    """``bid_view`` with only ``rows`` recomputed from ``previous`` (all rows without one): compiled
    (``kernels.bids.bid_rows``) when numba is there, else ``bid_view`` in full.

    The rows are rewritten in ``previous``'s arrays (a view describes the tables until they next change; copying
    (N, M) arrays at every bid cost more than the bids at 100 agents), and ``previous`` itself is returned with its
    cached ``can_bid`` dropped.
    """
    if not kernels.COMPILED:
        return bid_view(knowledge, scenario, equipment, equipment_match, gain, slot, prereq_mode=prereq_mode,
                        require_known_capacity=require_known_capacity, max_bundle=max_bundle, fillable=fillable,
                        bid_warping=bid_warping, outbid_ties=outbid_ties)
    n, m = gain.shape
    reuse = (previous is not None and previous.gain is gain and previous.slot is slot
             and previous.equipment_match is equipment_match)
    if reuse:
        arrays = [getattr(previous, name) for name in ROW_FIELDS]
    else:
        rows = range(n)
        arrays = [np.zeros((n, m), dtype=np.int64 if name in ("members", "displaced") else
                           bool if name in ("outbid", "eligible", "prereqs_met", "in_bundle") else float)
                  for name in ROW_FIELDS]
    capacity = (known_capacity(knowledge, scenario, equipment, equipment_match) if require_known_capacity
                else _everyone_known(n, m))
    groups = knowledge.groups
    task_agents = np.asarray(scenario.task_agents, dtype=np.int64)          # no copy when it is int64 already
    bid_rows(np.asarray(rows, dtype=np.int64), groups.count, groups.members, groups.bids, knowledge.single, gain,
             knowledge.quit_blocked, np.fromiter(map(len, knowledge.bundles), dtype=np.int64, count=n),
             equipment_match, fillable, capacity, task_agents, equipment.restricted,
             equipment.required, equipment.agent, scenario.task_prereqs, PREREQ_MODES[prereq_mode], int(max_bundle),
             bid_warping, outbid_ties == "strict", *arrays)
    if reuse:                       # the same arrays, rewritten: only the derived valid-bid mask is stale
        previous.__dict__.pop("can_bid", None)
        return previous
    return BidView(gain=gain, slot=slot, equipment_match=equipment_match, **dict(zip(ROW_FIELDS, arrays)))
