"""The asynchronous two-pass merge ``group_merge.merge_stamped`` (CBGA's Alg 6 l. 7–23 with per-entry times; our
extension of Johnson's ACBBA to multi-agent tasks, docs/algorithm.md §9.6, docs/decisions.md "merge" row).

The rules under test, stated from the documents rather than the code:

* Pass A: a member m ≠ i of the receiver's column is replaced by the sender's entry (a bid, or 0 if withdrawn) only
  if the sender's time for it is *newer* (t_k > t_i); an older or equal time never replaces it;
* Pass B: a sender member the receiver does not hold is offered to the admission test (``groups.admit``: room and
  needed equipment, else displacing the (bid, id)-lowest same-equipment member it outbids) if its time is *not older*
  than the receiver's record of it (t_k ≥ t_i). An equal time marks an entry the receiver zeroed only because it saw
  it displaced: once the displacer has gone it is re-admitted (the documented choice);
* the receiver is authoritative on its own row (only a displacement in Pass B can remove it);
* returned times: the sender's for the entries copied (refreshed in Pass A, admitted in Pass B), the receiver's
  otherwise, so a displaced or rejected entry keeps the receiver's time;
* at most L_j members after the merge; merging a column with itself changes nothing.

The synchronous ``merge`` (tests/test_group_merge.py) runs the same ``two_pass``; these cases repeat its unit tests
with times in place of per-agent timestamps.
"""

from __future__ import annotations

import helpers
import numpy as np
from helpers import draw_group_setup, examples, typed
from hypothesis import given, settings
from hypothesis import strategies as st

from taskalloc_env.group_merge import merge_stamped
from taskalloc_env.groups import Equipment
from taskalloc_env.stamps import NEVER, stamp, tick_of

N_AGENTS = 6
RECEIVER, SENDER = 0, 1
Entries = dict[int, tuple[float, int]]          # agent -> (bid, tick of the entry's time); absent: (0, never)


def column(entries: Entries, n: int = N_AGENTS) -> tuple[np.ndarray, np.ndarray]:
    """One (1, n, 1) column and its times; an entry's time is stamped by the agent it is about."""
    bids = np.zeros((1, n, 1))
    times = np.full((1, n, 1), NEVER, dtype=np.int64)
    for agent, (bid, tick) in entries.items():
        bids[0, agent, 0] = bid
        times[0, agent, 0] = stamp(tick, agent)
    return bids, times


def members(bids: np.ndarray) -> dict[int, float]:
    return {int(a): float(bids[0, a, 0]) for a in np.flatnonzero(bids[0, :, 0] > 0)}


def ticks(times: np.ndarray) -> dict[int, int]:
    return {int(a): int(tick_of(times[0, a, 0])) for a in np.flatnonzero(times[0, :, 0] != NEVER)}


def no_equipment(n: int = N_AGENTS) -> Equipment:
    return helpers.no_equipment(n)


def merged(receiver: Entries, sender: Entries, required: int, *, equipment: Equipment | None = None,
           receiver_id: int = RECEIVER) -> tuple[np.ndarray, np.ndarray]:
    bids_i, t_i = column(receiver)
    bids_k, t_k = column(sender)
    return merge_stamped(bids_i, t_i, bids_k, t_k, np.array([receiver_id]), np.array([required]),
                         equipment or no_equipment())


def run(receiver: Entries, sender: Entries, required: int, **kw) -> dict[int, float]:
    """The receiver's members after merging ``sender`` into ``receiver``."""
    return members(merged(receiver, sender, required, **kw)[0])


# -- Pass A: newer replaces older, older or equal never ----------------------------------------------------------------
def test_a_newer_entry_replaces_an_older_one():
    assert run({0: (50, 5), 2: (40, 5)}, {2: (55, 6)}, 3) == {0: 50, 2: 55}


def test_an_older_entry_never_replaces_a_newer_one():
    assert run({0: (50, 5), 2: (40, 6)}, {2: (55, 5)}, 3) == {0: 50, 2: 40}
    assert run({0: (50, 5), 2: (40, 6)}, {2: (0, 5)}, 3) == {0: 50, 2: 40}         # an older withdrawal


def test_an_equal_time_does_not_refresh_a_member():
    """Equal times are the same stamping event (``stamps``: unique per event); Pass A needs t_k > t_i."""
    assert run({0: (50, 5), 2: (40, 6)}, {2: (0, 6)}, 3) == {0: 50, 2: 40}


def test_a_newer_withdrawal_removes_a_member_and_carries_its_time():
    bids, times = merged({0: (50, 5), 2: (40, 5)}, {2: (0, 7), 3: (10, 1)}, 3)
    assert members(bids) == {0: 50, 3: 10}
    assert ticks(times) == {0: 5, 2: 7, 3: 1}


def test_receiver_is_authoritative_on_its_own_row():
    """A newer sender entry about the receiver, a bid or a withdrawal, changes neither its bid nor its time."""
    for entry in [(0, 9), (70, 9)]:
        bids, times = merged({0: (50, 5), 2: (40, 5)}, {0: entry, 2: (40, 5)}, 3)
        assert members(bids) == {0: 50, 2: 40}
        assert ticks(times) == {0: 5, 2: 5}
    assert run({2: (40, 5)}, {0: (70, 9)}, 3) == {2: 40}          # nor does Pass B admit the receiver on another's word


# -- Pass B: newcomers -------------------------------------------------------------------------------------------------
def test_newcomers_with_a_newer_time_enter_free_room():
    assert run({0: (50, 5)}, {SENDER: (60, 6), 2: (40, 6)}, 3) == {0: 50, SENDER: 60, 2: 40}


def test_an_older_newcomer_is_not_offered():
    """The receiver's record of agent 2 (a withdrawal at tick 6) is newer than the sender's bid of tick 5."""
    assert run({0: (50, 5), 2: (0, 6)}, {2: (90, 5)}, 3) == {0: 50}


def test_room_is_filled_best_first_then_the_minimum_is_replaced():
    assert run({0: (50, 5)}, {SENDER: (30, 6), 2: (70, 6), 3: (20, 6)}, 2) == {0: 50, 2: 70}


def test_full_group_replaces_its_bid_id_minimum_and_ties_go_to_the_higher_id():
    full = {2: (50, 5), 3: (45, 5)}
    assert run(full, {4: (47, 6)}, 2) == {2: 50, 4: 47}
    assert run(full, {4: (44, 6)}, 2) == {2: 50, 3: 45}
    tie = {2: (50, 5), 3: (50, 5)}
    assert run(tie, {4: (50, 6)}, 2) == {3: 50, 4: 50}                  # (50, 4) ≻ (50, 2)
    assert run(tie, {SENDER: (50, 6)}, 2) == {2: 50, 3: 50}             # (50, 1) does not beat (50, 2)


def test_receiver_itself_can_be_displaced_and_keeps_its_time():
    """n* may be i (Alg 6 l. 18–20): how the receiver learns it lost; its entry keeps its own time."""
    bids, times = merged({RECEIVER: (30, 5), 2: (50, 5)}, {SENDER: (40, 6)}, 2)
    assert members(bids) == {SENDER: 40, 2: 50}
    assert ticks(times) == {RECEIVER: 5, SENDER: 6, 2: 5}
    assert run({RECEIVER: (45, 5), 2: (50, 5)}, {SENDER: (40, 6)}, 2) == {RECEIVER: 45, 2: 50}


def test_returned_times_are_the_senders_for_copied_entries_and_the_receivers_otherwise():
    """Refreshed (2) and admitted (4): the sender's times; displaced (3) and rejected (5): the receiver's."""
    receiver = {0: (60, 5), 2: (40, 5), 3: (30, 5), 5: (0, 4)}
    sender = {2: (45, 8), 3: (30, 5), 4: (35, 9), 5: (10, 7)}
    bids, times = merged(receiver, sender, 3)
    assert members(bids) == {0: 60, 2: 45, 4: 35}
    assert ticks(times) == {0: 5, 2: 8, 3: 5, 4: 9, 5: 4}


# -- re-admission of a displaced member (docs/decisions.md "merge" row) ------------------------------------------------
def test_a_displaced_member_is_readmitted_once_its_displacer_is_gone():
    """Agent 3 (bid 40, tick 4) is displaced at the receiver by 4 (45, tick 6); the receiver holds 3 at 0 with 3's own
    time. When 4 withdraws (tick 7) and 3 — which never learned it lost — repeats its unchanged entry, the equal time
    offers it to the admission test again, and it re-enters the free slot."""
    bids, times = merged({2: (50, 5), 3: (40, 4)}, {4: (45, 6)}, 2)
    assert members(bids) == {2: 50, 4: 45} and ticks(times)[3] == 4
    bids_k, t_k = column({4: (0, 7)})
    bids, times = merge_stamped(bids, times, bids_k, t_k, np.array([RECEIVER]), np.array([2]), no_equipment())
    assert members(bids) == {2: 50}
    bids_k, t_k = column({3: (40, 4)})
    again, again_t = merge_stamped(bids, times, bids_k, t_k, np.array([RECEIVER]), np.array([2]), no_equipment())
    assert members(again) == {2: 50, 3: 40}
    assert ticks(again_t)[3] == 4


def test_a_displaced_member_stays_out_while_its_displacer_holds():
    assert run({2: (50, 5), 3: (0, 4), 4: (45, 6)}, {3: (40, 4)}, 2) == {2: 50, 4: 45}


def test_a_stale_copy_of_a_displaced_member_is_not_readmitted():
    """A record older than the receiver's (3 withdrew at tick 6) does not bring 3 back, even with room."""
    assert run({2: (50, 5), 3: (0, 6)}, {3: (40, 4)}, 2) == {2: 50}


# -- equipment (thesis (3.15)) -----------------------------------------------------------------------------------------
TYPES = ["A", "A", "A", "B", "B", "C"]          # agents 0-2 type A, 3-4 type B, 5 type C


def test_equipment_room_only_for_a_needed_type():
    eq = typed(TYPES, {"A": 1, "B": 1})
    assert run({RECEIVER: (50, 5)}, {3: (10, 6)}, 2, equipment=eq) == {RECEIVER: 50, 3: 10}
    assert run({RECEIVER: (50, 5)}, {2: (40, 6)}, 2, equipment=eq) == {RECEIVER: 50}


def test_equipment_newcomer_replaces_only_same_equipment():
    eq = typed(TYPES, {"A": 1, "B": 1})
    assert run({RECEIVER: (50, 5)}, {2: (60, 6)}, 2, equipment=eq) == {2: 60}
    full = {RECEIVER: (50, 5), 3: (40, 5)}
    assert run(full, {2: (45, 6)}, 2, equipment=eq) == {RECEIVER: 50, 3: 40}        # the B at 40 is not replaceable
    assert run(full, {4: (45, 6)}, 2, equipment=eq) == {RECEIVER: 50, 4: 45}


def test_equipment_no_slot_for_an_unneeded_type():
    eq = typed(TYPES, {"A": 2})
    assert run({RECEIVER: (50, 5)}, {5: (99, 6)}, 2, equipment=eq) == {RECEIVER: 50}
    assert run({}, {5: (99, 6)}, 2, equipment=eq) == {}


# -- properties ------------------------------------------------------------------------------------------------------
@st.composite
def stamped_inputs(draw):
    """R receivers' columns and their senders' columns with entry times in 0..3 (0 = ``NEVER``), capacity respected."""
    n, m, r, required, agent_eq, task_eq = draw_group_setup(draw)
    bid = st.sampled_from([0.0, 0.0, 10.0, 20.0, 30.0, 40.0])

    def table() -> tuple[np.ndarray, np.ndarray]:
        cols = np.array([[[draw(bid) for _ in range(m)] for _ in range(n)] for _ in range(r)])
        for q in range(r):
            for j in range(m):
                holders = np.flatnonzero(cols[q, :, j] > 0)
                cols[q, holders[required[j]:], j] = 0.0
        times = np.array([[[draw(st.integers(0, 3)) for _ in range(m)] for _ in range(n)] for _ in range(r)],
                         dtype=np.int64)
        times[(cols > 0) & (times == NEVER)] = 1                      # a bid always has a time
        return cols, times

    bids_i, t_i = table()
    bids_k, t_k = table()
    receivers = np.array([draw(st.integers(0, n - 1)) for _ in range(r)])
    return bids_i, t_i, bids_k, t_k, receivers, required, Equipment(agent_eq, task_eq)


@settings(max_examples=examples(300), deadline=None)
@given(stamped_inputs())
def test_merge_stamped_properties(inputs):
    """Capacity ((3.4)), the receiver's own row, newer-replaces-older, the origin of every value and time, equipment
    never in surplus ((3.15)), and the vectorised call equals one call per receiver."""
    bids_i, t_i, bids_k, t_k, receivers, required, eq = inputs
    out, out_t = merge_stamped(bids_i.copy(), t_i.copy(), bids_k, t_k, receivers, required, eq)
    r_count, n, _ = bids_i.shape
    own = (np.arange(n)[None, :] == receivers[:, None])[:, :, None]
    # at most L_j members
    assert np.all((out > 0).sum(axis=1) <= required[None, :])
    # every value and time comes from one of the two views
    assert np.all((out == bids_i) | (out == bids_k) | (out == 0))
    assert np.all((out_t == t_i) | (out_t == t_k))
    # the receiver is authoritative on its own row: its time never moves, its bid can only be displaced
    assert np.all(np.where(own, out_t == t_i, True))
    assert np.all(np.where(own, (out == bids_i) | (out == 0), True))
    # an older or equal entry never replaces a member (its bid and time stay, unless a newcomer displaced it)
    kept = (bids_i > 0) & (t_k <= t_i)
    assert np.all(np.where(kept, out_t == t_i, True))
    assert np.all(np.where(kept, (out == bids_i) | (out == 0), True))
    # a newer entry replaces a member (bid or withdrawal, with its time; it may be displaced afterwards in Pass B)
    refreshed = (bids_i > 0) & (t_k > t_i) & ~own
    assert np.all(np.where(refreshed, out_t == t_k, True))
    assert np.all(np.where(refreshed, (out == bids_k) | (out == 0), True))
    # a newcomer enters only with the sender's bid and time, never older than the receiver's record, never as i
    admitted = (bids_i == 0) & (out > 0)
    assert np.all(np.where(admitted, (out == bids_k) & (out_t == t_k) & (t_k >= t_i) & ~own, True))
    # a member leaves only by a newer withdrawal or when a newcomer displaces it
    dropped = (bids_i > 0) & (out == 0) & ~(refreshed & (bids_k == 0))
    assert np.all(~dropped.any(axis=1) | admitted.any(axis=1))
    # the times: the sender's exactly for the copied entries
    np.testing.assert_array_equal(out_t, np.where(refreshed | admitted, t_k, t_i))
    # equipment: a restricted task never gains a surplus type
    if eq.any:
        have = np.einsum("rnm,ne->rme", (out > 0).astype(int), eq.agent.astype(int))
        have_before = np.einsum("rnm,ne->rme", (bids_i > 0).astype(int), eq.agent.astype(int))
        grew = have > np.maximum(have_before, eq.required[None])
        assert not (grew & eq.restricted[None, :, None]).any(), "a restricted task gained a surplus type"
    for q in range(r_count):
        alone, alone_t = merge_stamped(bids_i[q:q + 1].copy(), t_i[q:q + 1].copy(), bids_k[q:q + 1], t_k[q:q + 1],
                                       receivers[q:q + 1], required, eq)
        np.testing.assert_array_equal(alone[0], out[q])
        np.testing.assert_array_equal(alone_t[0], out_t[q])


@settings(max_examples=examples(200), deadline=None)
@given(stamped_inputs())
def test_merging_a_column_with_itself_changes_nothing(inputs):
    bids_i, t_i, _, _, receivers, required, eq = inputs
    out, out_t = merge_stamped(bids_i.copy(), t_i.copy(), bids_i.copy(), t_i.copy(), receivers, required, eq)
    np.testing.assert_array_equal(out, bids_i)
    np.testing.assert_array_equal(out_t, t_i)
