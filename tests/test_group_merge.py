"""The two-pass merge of multi-agent task columns (thesis §3.2.3, Alg 6 with its guards, eq. (3.15); ties to the
higher id; capacity, same-equipment replacement and the top-L_j property).

Each case builds one receiver column and one sender column by hand and states the expected column from the rules:
Pass A refreshes the receiver's members (the sender is trusted for m if m = k or s_k[m] > s_i[m]; the receiver is
authoritative on its own row); Pass B imports trusted newcomers, best (bid, id) first, into free slots whose
equipment is still needed, otherwise displacing the (bid, id)-minimum same-equipment member it outbids.
"""

from __future__ import annotations

import helpers
import numpy as np
from helpers import draw_group_setup, examples, typed
from hypothesis import given, settings
from hypothesis import strategies as st

from taskalloc_env.group_merge import merge
from taskalloc_env.groups import Equipment

N_AGENTS = 6
RECEIVER, SENDER = 0, 1


def column(entries: dict[int, float], n: int = N_AGENTS) -> np.ndarray:
    col = np.zeros((1, n, 1))
    for agent, bid in entries.items():
        col[0, agent, 0] = bid
    return col


def as_dict(col: np.ndarray) -> dict[int, float]:
    return {int(a): float(col[0, a, 0]) for a in np.flatnonzero(col[0, :, 0] > 0)}


def no_equipment(n: int = N_AGENTS) -> Equipment:
    return helpers.no_equipment(n)


def run(receiver: dict, sender: dict, required: int, *, fresher: tuple[int, ...] = (), staler: tuple[int, ...] = (),
        equipment: Equipment | None = None, receiver_id: int = RECEIVER, sender_id: int = SENDER) -> dict:
    """Merge ``sender`` into ``receiver``; the sender is fresher about ``fresher`` agents, staler about ``staler``."""
    s_i = np.full((1, N_AGENTS), 5.0)
    s_k = np.full((1, N_AGENTS), 5.0)           # equal stamps: not trusted unless m == k
    for a in fresher:
        s_k[0, a] = 6.0
    for a in staler:
        s_k[0, a] = 4.0
    out = merge(column(receiver), column(sender), np.array([receiver_id]), np.array([sender_id]), s_i, s_k,
                np.array([required]), equipment or no_equipment())
    return as_dict(out)


# -- Pass A ------------------------------------------------------------------------------------------------------
def test_pass_a_refreshes_a_member_the_sender_heard_from_more_recently():
    assert run({0: 50, 2: 40}, {2: 55}, 3, fresher=(2,)) == {0: 50, 2: 55}


def test_pass_a_keeps_a_member_when_the_sender_is_not_fresher():
    assert run({0: 50, 2: 40}, {2: 55}, 3, staler=(2,)) == {0: 50, 2: 40}
    assert run({0: 50, 2: 40}, {2: 55}, 3) == {0: 50, 2: 40}            # equal stamps are not fresher


def test_pass_a_removes_a_member_that_left():
    """The fresher sender no longer lists member 2: it left or was displaced (its entry becomes 0)."""
    assert run({0: 50, 2: 40}, {3: 10}, 3, fresher=(2,)) == {0: 50}


def test_pass_a_trusts_the_sender_about_its_own_row():
    """m = k: the sender speaks for its own bid even when its stamp of itself is not newer (Alg 6 line 8)."""
    assert run({0: 50, SENDER: 40}, {}, 3, staler=(SENDER,)) == {0: 50}
    assert run({0: 50, SENDER: 40}, {SENDER: 45}, 3, staler=(SENDER,)) == {0: 50, SENDER: 45}


def test_receiver_is_authoritative_on_its_own_row():
    """Pass A skips m = i: a sender that no longer lists the receiver does not remove it (only Pass B can)."""
    assert run({0: 50, 2: 40}, {2: 40}, 3, fresher=(0, 2)) == {0: 50, 2: 40}
    assert run({0: 50}, {0: 70}, 3, fresher=(0,)) == {0: 50}


# -- Pass B ------------------------------------------------------------------------------------------------------
def test_pass_b_adds_trusted_newcomers_into_room():
    assert run({0: 50}, {SENDER: 60, 2: 40}, 3, fresher=(2,)) == {0: 50, SENDER: 60, 2: 40}


def test_pass_b_ignores_untrusted_newcomers():
    assert run({0: 50}, {2: 90}, 3, staler=(2,)) == {0: 50}
    assert run({0: 50}, {2: 90}, 3) == {0: 50}


def test_pass_b_fills_room_best_first_and_then_replaces_the_minimum():
    """Room for one: the best newcomer takes it, the next one must beat the group minimum."""
    got = run({0: 50}, {SENDER: 30, 2: 70, 3: 20}, 2, fresher=(2, 3))
    assert got == {0: 50, 2: 70}


def test_full_group_replaces_its_bid_id_minimum():
    receiver = {2: 50, 3: 45}
    assert run(receiver, {4: 47}, 2, fresher=(4,)) == {2: 50, 4: 47}      # 47 beats the minimum 45
    assert run(receiver, {4: 44}, 2, fresher=(4,)) == receiver            # 44 does not


def test_full_group_ties_go_to_the_higher_id():
    """(bid, id) order: with equal bids the lower id is the minimum and a higher-id newcomer displaces it."""
    receiver = {2: 50, 3: 50}
    assert run(receiver, {4: 50}, 2, fresher=(4,)) == {3: 50, 4: 50}      # (50, 4) ≻ (50, 2)
    assert run(receiver, {SENDER: 50}, 2) == receiver                     # (50, 1) does not beat (50, 2)


def test_receiver_itself_can_be_displaced():
    """n* may be i: that is how the receiver learns it lost the task (Alg 6 l. 18–20)."""
    assert run({RECEIVER: 30, 2: 50}, {SENDER: 40}, 2) == {SENDER: 40, 2: 50}
    assert run({RECEIVER: 45, 2: 50}, {SENDER: 40}, 2) == {RECEIVER: 45, 2: 50}


def test_members_are_the_top_l_of_both_views_without_equipment():
    """Pass B keeps the better of the incoming bid and the group minimum: the group becomes the top-L bidders."""
    got = run({RECEIVER: 10, 2: 30, 3: 50}, {SENDER: 20, 4: 40, 5: 60}, 3, fresher=(4, 5))
    assert got == {3: 50, 4: 40, 5: 60}


# -- equipment (3.15) ----------------------------------------------------------------------------------------------
TYPES = ["A", "A", "A", "B", "B", "C"]          # agents 0-2 type A, 3-4 type B, 5 type C


def test_equipment_room_only_for_a_needed_type():
    """te = {A, B}, one A member: a second A has no slot, a B takes the free one (thesis §3.2.3 equipment text)."""
    eq = typed(TYPES, {"A": 1, "B": 1})
    assert run({RECEIVER: 50}, {3: 10}, 2, fresher=(3,), equipment=eq) == {RECEIVER: 50, 3: 10}
    assert run({RECEIVER: 50}, {2: 40}, 2, fresher=(2,), equipment=eq) == {RECEIVER: 50}


def test_equipment_newcomer_replaces_only_same_equipment():
    """A better same-type bid displaces the same-type member; it never displaces a cheaper member of another type."""
    eq = typed(TYPES, {"A": 1, "B": 1})
    assert run({RECEIVER: 50}, {2: 60}, 2, fresher=(2,), equipment=eq) == {2: 60}
    full = {RECEIVER: 50, 3: 40}
    assert run(full, {2: 45}, 2, fresher=(2,), equipment=eq) == full            # the B at 40 is not replaceable
    assert run(full, {4: 45}, 2, fresher=(4,), equipment=eq) == {RECEIVER: 50, 4: 45}


def test_equipment_no_slot_for_an_unneeded_type():
    """te = {A, A}: a C agent never joins, not even into free room, whatever its bid."""
    eq = typed(TYPES, {"A": 2})
    assert run({RECEIVER: 50}, {5: 99}, 2, fresher=(5,), equipment=eq) == {RECEIVER: 50}
    assert run({}, {5: 99}, 2, fresher=(5,), equipment=eq) == {}


def test_equipment_tie_break_within_the_same_type():
    eq = typed(TYPES, {"A": 1, "B": 1})
    assert run({SENDER: 50, 3: 40}, {2: 50}, 2, fresher=(2,), equipment=eq, sender_id=4) == {2: 50, 3: 40}
    assert run({2: 50, 3: 40}, {SENDER: 50}, 2, equipment=eq) == {2: 50, 3: 40}


# -- Appendix A.2 round 1 at agent A2 (thesis App. A.2, Tables A.5, A.6, A.8) ---------------------------------------
def test_appendix_a2_merge_is_independent_of_sender_order():
    """A2 merges A1's and A3's first bids on T3 (L = 2, all 72.4): the two higher ids stay, whatever the order."""
    a2 = {1: 72.4}
    from_a1 = {0: 72.4}
    from_a3 = {2: 72.4}
    s_i = np.zeros((1, N_AGENTS))
    s_k = np.zeros((1, N_AGENTS))

    def step(col, msg, sender):
        return merge(col, column(msg), np.array([1]), np.array([sender]), s_i, s_k, np.array([2]), no_equipment())

    first = step(step(column(a2), from_a1, 0), from_a3, 2)
    second = step(step(column(a2), from_a3, 2), from_a1, 0)
    assert as_dict(first) == as_dict(second) == {1: 72.4, 2: 72.4}


# -- properties ----------------------------------------------------------------------------------------------------
@st.composite
def merge_inputs(draw):
    n, m, r, required, agent_eq, task_eq = draw_group_setup(draw)
    bid = st.sampled_from([0.0, 0.0, 10.0, 20.0, 30.0, 40.0])

    def table():
        cols = np.array([[[draw(bid) for _ in range(m)] for _ in range(n)] for _ in range(r)])
        for q in range(r):                        # respect capacity in each input column
            for j in range(m):
                holders = np.flatnonzero(cols[q, :, j] > 0)
                cols[q, holders[required[j]:], j] = 0.0
        return cols

    receivers = np.array([draw(st.integers(0, n - 1)) for _ in range(r)])
    senders = np.array([(x + 1 + draw(st.integers(0, n - 2))) % n for x in receivers])
    s_i = np.array([[draw(st.integers(0, 3)) for _ in range(n)] for _ in range(r)], dtype=float)
    s_k = np.array([[draw(st.integers(0, 3)) for _ in range(n)] for _ in range(r)], dtype=float)
    return table(), table(), receivers, senders, s_i, s_k, required, Equipment(agent_eq, task_eq)


@settings(max_examples=examples(300), deadline=None)
@given(merge_inputs())
def test_merge_properties(inputs):
    """Capacity (thesis (3.4)), entries come from one of the two views, the receiver's row only shrinks, same-type
    parity ((3.15)), equipment never in surplus, and the vectorised call equals one call per receiver."""
    bids_i, bids_k, receivers, senders, s_i, s_k, required, eq = inputs
    out = merge(bids_i.copy(), bids_k, receivers, senders, s_i, s_k, required, eq)
    assert np.all((out > 0).sum(axis=1) <= required[None, :])
    assert np.all((out == bids_i) | (out == bids_k) | (out == 0))
    rows = np.arange(len(receivers))
    own_before = bids_i[rows, receivers, :]
    own_after = out[rows, receivers, :]
    assert np.all((own_after == own_before) | (own_after == 0))
    if eq.any:
        have = np.einsum("rnm,ne->rme", (out > 0).astype(int), eq.agent.astype(int))
        have_before = np.einsum("rnm,ne->rme", (bids_i > 0).astype(int), eq.agent.astype(int))
        grew = have > np.maximum(have_before, eq.required[None])
        assert not (grew & eq.restricted[None, :, None]).any(), "a restricted task gained a surplus type"
    for q in range(len(receivers)):
        alone = merge(bids_i[q:q + 1].copy(), bids_k[q:q + 1], receivers[q:q + 1], senders[q:q + 1], s_i[q:q + 1],
                      s_k[q:q + 1], required, eq)
        np.testing.assert_array_equal(alone[0], out[q])
