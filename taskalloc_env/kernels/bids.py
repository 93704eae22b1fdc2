"""The bid view of chosen agents, compiled; ``bidding.bid_view`` (numpy, all agents at once) is the reference.

``bid_rows`` recomputes rows of the ``BidView`` arrays: the warped bid, the outbid test of Alg 5 l. 8–20 with the
group rules of ``groups`` (room, the displaced (bid, id)-lowest replaceable member), the prerequisite filter of
``prereq_mode`` and the eligibility filters, reading only each agent's own table. A bid changes only the bidder's
row, so between rounds the protocol refreshes only those rows. Comparisons, a running minimum and a sum over
the members in agent order (the order numpy sums the reference's columns in): results are bit-identical to the
reference (``tests/test_kernels.py``).
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.kernels import jit
from taskalloc_env.kernels.merge import NONE, _outbids, _replaceable, _value_of

ALL_HAVE_BID, ALL_COMPLETE, ANY_HAS_BID = 0, 1, 2
PREREQ_MODES = {"all_have_bid": ALL_HAVE_BID, "all_complete": ALL_COMPLETE, "any_has_bid": ANY_HAS_BID}


@jit
def _covered(have: np.ndarray, required: np.ndarray) -> bool:
    """``Equipment.covers`` from the items the members carry: they include te_j as a multiset, (3.5)."""
    for e in range(required.size):  # noqa: SIM110 - compiled: an explicit loop, not a generator
        if have[e] < required[e]:
            return False
    return True


@jit
def _fills(have: np.ndarray, newcomer: int, required: np.ndarray, agent_eq: np.ndarray) -> bool:
    """``Equipment.slot_open`` from the items the members carry: the newcomer meets an unmet item of te_j."""
    for e in range(required.size):  # noqa: SIM110 - compiled: an explicit loop, not a generator
        if agent_eq[newcomer, e] and required[e] > have[e]:
            return True
    return False


@jit
def bid_rows(rows: np.ndarray, count: np.ndarray, ids: np.ndarray, values: np.ndarray, single: np.ndarray,
             gain: np.ndarray, quit_blocked: np.ndarray, bundle_sizes: np.ndarray, equipment_match: np.ndarray,
             fillable: np.ndarray, capacity: np.ndarray, need: np.ndarray, restricted: np.ndarray,
             required: np.ndarray, agent_eq: np.ndarray, prereqs: np.ndarray, prereq_mode: int, max_bundle: int,
             warping: bool, strict: bool, bid: np.ndarray, outbid: np.ndarray, eligible: np.ndarray,
             prereqs_met: np.ndarray, members: np.ndarray, group_total: np.ndarray, lowest_bid: np.ndarray,
             displaced: np.ndarray, displaced_bid: np.ndarray, in_bundle: np.ndarray) -> None:
    """Fill rows ``rows`` of the (N, M) view arrays in place (see ``bidding.BidView`` for their meaning) from the
    ``GroupTable`` arrays: ``count`` (N, M), member ``ids`` and their bid ``values`` (N, M, W), ids increasing."""
    m = count.shape[1]
    n_items = required.shape[1]
    any_prereqs = prereqs.any()
    complete_prereqs = any_prereqs and prereq_mode == ALL_COMPLETE     # reads every column's items
    have = np.zeros((m, n_items), dtype=np.int64)                # items the members carry, per column
    for i in rows:
        lowest_own = np.inf
        for j in range(m):
            in_bundle[i, j] = _value_of(i, count[i, j], ids[i, j], values[i, j]) > 0
            if in_bundle[i, j]:
                lowest_own = min(lowest_own, _value_of(i, count[i, j], ids[i, j], values[i, j]))
        have[:, :] = 0
        for j in range(m):
            if complete_prereqs or restricted[j]:                # the items only these two rules read
                for c in range(count[i, j]):
                    for e in range(n_items):
                        if agent_eq[ids[i, j, c], e]:
                            have[j, e] += 1
            b = min(gain[i, j], lowest_own) if warping else gain[i, j]
            bid[i, j] = b
            if single[j]:
                w = ids[i, j, 0]
                held = values[i, j, 0]
                members[i, j] = count[i, j]
                group_total[i, j] = held
                lowest_bid[i, j] = held
                better = b > held if strict else _outbids(b, i, held, w)
                outbid[i, j] = w == NONE or better
                displaced[i, j] = w
                displaced_bid[i, j] = held
                continue
            # one pass over the members in id order: count, total, lowest bid and lowest replaceable member
            total, lowest, victim, victim_bid = 0.0, np.inf, -1, 0.0
            for c in range(count[i, j]):
                k, value = ids[i, j, c], values[i, j, c]
                total += value
                lowest = min(lowest, value)
                if (not restricted[j] or _replaceable(k, i, required[j], agent_eq)) \
                        and (victim < 0 or value < victim_bid):
                    victim, victim_bid = k, value
            n_members = count[i, j]
            members[i, j] = n_members
            group_total[i, j] = total
            lowest_bid[i, j] = lowest if n_members > 0 else 0.0
            room = n_members < need[j] and (not restricted[j] or _fills(have[j], i, required[j], agent_eq))
            beats = False
            if not room and victim >= 0:
                beats = b > victim_bid if strict else _outbids(b, i, victim_bid, victim)
            outbid[i, j] = room or beats
            displaced[i, j] = victim if beats else NONE
            displaced_bid[i, j] = victim_bid if beats else 0.0
        for j in range(m):                                   # prerequisites ((3.6), article eq. (5))
            met = True
            if any_prereqs:
                if prereq_mode == ANY_HAS_BID:
                    has, some = False, False
                    for p in range(m):
                        if prereqs[j, p]:
                            has = True
                            some = some or members[i, p] > 0
                    met = some or not has
                else:
                    for p in range(m):
                        if prereqs[j, p]:
                            if prereq_mode == ALL_HAVE_BID:
                                done = members[i, p] > 0
                            else:
                                done = members[i, p] == need[p] and _covered(have[p], required[p])
                            if not done:
                                met = False
                                break
            prereqs_met[i, j] = met
            eligible[i, j] = (equipment_match[i, j] and met and not in_bundle[i, j] and fillable[j]
                              and capacity[i, j] and not quit_blocked[i, j] and bundle_sizes[i] < max_bundle)
