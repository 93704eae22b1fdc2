"""Johnson Table 4.1 (ACBBA decision rules, §4.1.2), cell by cell: the sender's and the receiver's beliefs and times,
the expected action, the receiver's record afterwards and whether it is rebroadcast.

Agents: the receiver i, the sender k, third agents m and n. Times are ``stamps`` triples: ``T(tick, by)`` is a bid
made (or an empty bid sent) at ``tick`` by agent ``by``; the receiver acts at tick NOW. Rows follow the numbering of
Johnson's remarks (extraction lines 873–906); row 0 is the header's default, leave & rebroadcast (line 832).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from taskalloc_env import acbba_table as tb
from taskalloc_env.cbba_table import NONE
from taskalloc_env.stamps import MAX_BUMPS, NEVER, bump, bumps_of, stamp, stamper_of, tick_of

I, K, M, N = 2, 5, 7, 9  # noqa: E741 -- receiver, sender, third agents (k > i: the receiver wins a tie by the lowest id)
NOW = 50
E = NONE


def T(tick: int, by: int) -> int:
    return int(stamp(tick, by))


def B(time: int, by: int) -> int:
    """time + ε, bumped by ``by``."""
    return int(bump(time, by))


# (row, sender's (z, y, t), receiver's (z, y, t), expected action, expected receiver record afterwards, options)
# the record "same" means unchanged; a record's time None means "the current time", stamped by the receiver
CELLS = [
    # -- sender thinks k, receiver thinks i (rows 1-3, remark line 875) --
    ("1: y_k > y_i, sender's time later", (K, 6.0, T(12, K)), (I, 5.0, T(10, I)), tb.OUTBID, (K, 6.0, T(12, K)), {}),
    ("1: y_k > y_i, sender's time earlier: the sender's record (outbid_time default)", (K, 6.0, T(8, K)),
     (I, 5.0, T(10, I)), tb.OUTBID, (K, 6.0, T(8, K)), {}),
    ("1: outbid_time=bump (the † reading): receiver's losing time + ε", (K, 6.0, T(8, K)), (I, 5.0, T(10, I)),
     tb.OUTBID, (K, 6.0, B(T(10, I), I)), {"outbid_time": "bump"}),
    ("2: tie, the sender's id is lower", (I, 5.0, T(8, I)), (K, 5.0, T(10, K)), tb.OUTBID, (I, 5.0, T(8, I)),
     {"receiver": K, "sender": I}),
    ("2: tie, outbid_time=bump", (I, 5.0, T(8, I)), (K, 5.0, T(10, K)), tb.OUTBID, (I, 5.0, B(T(10, K), K)),
     {"receiver": K, "sender": I, "outbid_time": "bump"}),
    ("3: y_k < y_i: update time past the sender's", (K, 4.0, T(12, K)), (I, 5.0, T(10, I)), tb.UPDATE_TIME,
     (I, 5.0, B(T(12, K), I)), {}),
    ("3: y_k < y_i, own time already later: unchanged", (K, 4.0, T(8, K)), (I, 5.0, T(10, I)), tb.UPDATE_TIME,
     "same", {}),
    ("3: the tie the receiver wins (lower id), as row 3", (K, 5.0, T(12, K)), (I, 5.0, T(10, I)), tb.UPDATE_TIME,
     (I, 5.0, B(T(12, K), I)), {}),
    ("3: time_refresh=now moves the time to the current tick", (K, 4.0, T(12, K)), (I, 5.0, T(10, I)),
     tb.UPDATE_TIME, (I, 5.0, T(NOW, I)), {"refresh": "now"}),
    ("2: ties=higher_id: the higher sender id wins the tie", (K, 5.0, T(12, K)), (I, 5.0, T(10, I)), tb.OUTBID,
     (K, 5.0, T(12, K)), {"ties": "higher_id"}),
    # -- sender thinks k, receiver thinks k (rows 4-6, line 876) --
    ("4: newer time", (K, 6.0, T(12, K)), (K, 6.0, T(10, K)), tb.UPDATE, (K, 6.0, T(12, K)), {}),
    ("5: equal times: sink", (K, 6.0, T(10, K)), (K, 6.0, T(10, K)), tb.LEAVE_QUIET, "same", {}),
    ("6: older time", (K, 6.0, T(8, K)), (K, 6.0, T(10, K)), tb.LEAVE_QUIET, "same", {}),
    # -- sender thinks k, receiver thinks m (rows 7-11, lines 877-879) --
    ("7: y_k > y_i, t_k > t_i", (K, 6.0, T(12, K)), (M, 5.0, T(10, M)), tb.UPDATE, (K, 6.0, T(12, K)), {}),
    ("7: y_k > y_i, t_k = t_i", (K, 6.0, T(10, M)), (M, 5.0, T(10, M)), tb.UPDATE, (K, 6.0, T(10, M)), {}),
    ("8: y_k < y_i, t_k < t_i", (K, 4.0, T(8, K)), (M, 5.0, T(10, M)), tb.LEAVE, "same", {}),
    ("8: y_k < y_i, t_k = t_i", (K, 4.0, T(10, M)), (M, 5.0, T(10, M)), tb.LEAVE, "same", {}),
    ("9: y_k = y_i, newer: trust the later time (equal_bids default)", (K, 5.0, T(12, K)), (M, 5.0, T(10, M)),
     tb.UPDATE, (K, 5.0, T(12, K)), {}),
    ("9: y_k = y_i, older: leave", (K, 5.0, T(8, K)), (M, 5.0, T(10, M)), tb.LEAVE, "same", {}),
    ("9: equal_bids=leave (the cell)", (K, 5.0, T(12, K)), (M, 5.0, T(10, M)), tb.LEAVE, "same",
     {"equal_bids": "leave"}),
    ("10: y_k < y_i, t_k > t_i", (K, 4.0, T(12, K)), (M, 5.0, T(10, M)), tb.UPDATE, (K, 4.0, T(12, K)), {}),
    ("11: y_k > y_i, t_k < t_i (cell: update)", (K, 6.0, T(8, K)), (M, 5.0, T(10, M)), tb.UPDATE,
     (K, 6.0, T(8, K)), {}),
    ("11: row11=trust_later keeps the later record", (K, 6.0, T(8, K)), (M, 5.0, T(10, M)), tb.LEAVE, "same",
     {"row11": "trust_later"}),
    # -- sender thinks k, receiver thinks none (row 12, line 881) --
    ("12: a new bid", (K, 6.0, T(12, K)), (E, 0.0, T(20, I)), tb.UPDATE, (K, 6.0, T(12, K)), {}),
    # -- sender thinks i (rows 13-16, lines 882-887) --
    ("13: equal times: sink", (I, 5.0, T(10, I)), (I, 5.0, T(10, I)), tb.LEAVE_QUIET, "same", {}),
    ("13: the receiver's time is older: adopt the newer time", (I, 5.0, B(T(10, I), M)), (I, 5.0, T(10, I)),
     tb.ADOPT_TIME, (I, 5.0, B(T(10, I), M)), {}),
    ("13: the sender's time is older: rebroadcast the newer", (I, 5.0, T(8, I)), (I, 5.0, T(10, I)),
     tb.LEAVE_REFRESH, "same", {}),
    ("13: newer time with another value: keep own bid, time past it", (I, 4.0, T(12, M)), (I, 5.0, T(10, I)),
     tb.LEAVE_REFRESH, (I, 5.0, B(T(12, M), I)), {}),
    ("14: reset, empty bid with the current time", (I, 5.0, T(10, I)), (K, 6.0, T(12, K)), tb.RESET_EMPTY,
     (E, 0.0, None), {}),
    ("15: leave‡: keep m, time past the sender's", (I, 5.0, T(12, K)), (M, 6.0, T(10, M)), tb.LEAVE_REFRESH,
     (M, 6.0, B(T(12, K), I)), {}),
    ("15: row15=leave", (I, 5.0, T(12, K)), (M, 6.0, T(10, M)), tb.LEAVE, "same", {"row15": "leave"}),
    ("15: row15=empty (not in the thesis)", (I, 5.0, T(12, K)), (M, 6.0, T(10, M)), tb.RESET_EMPTY,
     (E, 0.0, None), {"row15": "empty"}),
    ("16: empty bid with the current time", (I, 5.0, T(10, I)), (E, 0.0, T(8, I)), tb.EMPTY, (E, 0.0, None), {}),
    ("16: the current time is not later than the sender's: sender's + ε", (I, 5.0, T(NOW, K)), (E, 0.0, T(8, I)),
     tb.EMPTY, (E, 0.0, B(T(NOW, K), I)), {}),
    # -- sender thinks m, receiver thinks i (rows 17-19, lines 889-891) --
    ("17: outbid", (M, 6.0, T(12, M)), (I, 5.0, T(10, I)), tb.OUTBID, (M, 6.0, T(12, M)), {}),
    ("17: outbid by an older record: the sender's record", (M, 6.0, T(8, M)), (I, 5.0, T(10, I)), tb.OUTBID,
     (M, 6.0, T(8, M)), {}),
    ("17: outbid by an older record, outbid_time=bump: receiver's time + ε", (M, 6.0, T(8, M)), (I, 5.0, T(10, I)),
     tb.OUTBID, (M, 6.0, B(T(10, I), I)), {"outbid_time": "bump"}),
    ("18: tie, m has the lower id", (1, 5.0, T(12, 1)), (I, 5.0, T(10, I)), tb.OUTBID, (1, 5.0, T(12, 1)), {}),
    ("19: y_k < y_i: update time", (M, 4.0, T(12, M)), (I, 5.0, T(10, I)), tb.UPDATE_TIME,
     (I, 5.0, B(T(12, M), I)), {}),
    ("19: the tie the receiver wins, as row 19", (M, 5.0, T(12, M)), (I, 5.0, T(10, I)), tb.UPDATE_TIME,
     (I, 5.0, B(T(12, M), I)), {}),
    # -- sender thinks m, receiver thinks k (row 20, line 893) --
    ("20: newer time: update", (M, 6.0, T(12, M)), (K, 5.0, T(10, K)), tb.UPDATE, (M, 6.0, T(12, M)), {}),
    ("20: older time, guard on: leave", (M, 6.0, T(8, M)), (K, 5.0, T(10, K)), tb.LEAVE, "same", {}),
    ("20: older time, guard off (the cell): update", (M, 6.0, T(8, M)), (K, 5.0, T(10, K)), tb.UPDATE,
     (M, 6.0, T(8, M)), {"row20_guard": False}),
    # -- sender and receiver think m (rows 21-23, line 895) --
    ("21: newer time", (M, 6.0, T(12, M)), (M, 6.0, T(10, M)), tb.UPDATE, (M, 6.0, T(12, M)), {}),
    ("22: equal times: sink", (M, 6.0, T(10, M)), (M, 6.0, T(10, M)), tb.LEAVE_QUIET, "same", {}),
    ("23: older time: rebroadcast own", (M, 6.0, T(8, M)), (M, 6.0, T(10, M)), tb.LEAVE, "same", {}),
    # -- sender thinks m, receiver thinks n (rows 24-27, line 897) --
    ("24: y_k > y_i, t_k ≥ t_i", (M, 6.0, T(12, M)), (N, 5.0, T(10, N)), tb.UPDATE, (M, 6.0, T(12, M)), {}),
    ("25: y_k < y_i, t_k ≤ t_i", (M, 4.0, T(8, M)), (N, 5.0, T(10, N)), tb.LEAVE, "same", {}),
    ("26: y_k < y_i, t_k > t_i", (M, 4.0, T(12, M)), (N, 5.0, T(10, N)), tb.UPDATE, (M, 4.0, T(12, M)), {}),
    ("27: y_k > y_i, t_k < t_i", (M, 6.0, T(8, M)), (N, 5.0, T(10, N)), tb.LEAVE, "same", {}),
    ("0: m | n with equal bids, newer: trust the later time", (M, 5.0, T(12, M)), (N, 5.0, T(10, N)), tb.UPDATE,
     (M, 5.0, T(12, M)), {}),
    ("0: m | n with equal bids, equal_bids=leave: the default", (M, 5.0, T(12, M)), (N, 5.0, T(10, N)), tb.LEAVE,
     "same", {"equal_bids": "leave"}),
    # -- sender thinks m, receiver thinks none (row 28, lines 899-901) --
    ("28: newer time: update", (M, 6.0, T(12, M)), (E, 0.0, T(10, I)), tb.UPDATE, (M, 6.0, T(12, M)), {}),
    ("28: older time, guard on: leave", (M, 6.0, T(8, M)), (E, 0.0, T(10, I)), tb.LEAVE, "same", {}),
    ("28: older time, guard off (the cell): update", (M, 6.0, T(8, M)), (E, 0.0, T(10, I)), tb.UPDATE,
     (M, 6.0, T(8, M)), {"row28_guard": False}),
    # -- sender thinks none (rows 29-32, lines 903-906) --
    ("29: keep own bid, time past the sender's", (E, 0.0, T(12, K)), (I, 5.0, T(10, I)), tb.LEAVE_REFRESH,
     (I, 5.0, B(T(12, K), I)), {}),
    ("29: own time already later", (E, 0.0, T(8, K)), (I, 5.0, T(10, I)), tb.LEAVE_REFRESH, "same", {}),
    ("30: the sender dropped its bid", (E, 0.0, T(12, K)), (K, 6.0, T(10, K)), tb.UPDATE, (E, 0.0, T(12, K)), {}),
    ("31: newer empty bid: update", (E, 0.0, T(12, K)), (M, 6.0, T(10, M)), tb.UPDATE, (E, 0.0, T(12, K)), {}),
    ("0: none | m with an older empty bid: the default", (E, 0.0, T(8, K)), (M, 6.0, T(10, M)), tb.LEAVE, "same",
     {}),
    ("32: equal times: sink", (E, 0.0, T(10, K)), (E, 0.0, T(10, K)), tb.LEAVE_QUIET, "same", {}),
    ("32: newer: trust the later time", (E, 0.0, T(12, K)), (E, 0.0, T(10, M)), tb.UPDATE, (E, 0.0, T(12, K)), {}),
    ("32: older: rebroadcast own", (E, 0.0, T(8, K)), (E, 0.0, T(10, M)), tb.LEAVE, "same", {}),
]

TABLE_OPTIONS = ("row11", "row15", "row20_guard", "row28_guard", "ties", "equal_bids")


def _run(sender, receiver, options, vectorised=False):
    i, k = options.get("receiver", I), options.get("sender", K)
    table = {key: options[key] for key in TABLE_OPTIONS if key in options}
    arrays = [np.array([v]) for v in (*sender, *receiver)]
    z_k, y_k, t_k, z_i, y_i, t_i = arrays
    action, row = tb.decide(i, k, z_k, y_k, t_k, z_i, y_i, t_i, **table)
    z, y, t, rebroadcast = tb.apply(action, i, NOW, z_i, y_i, t_i, z_k, y_k, t_k, options.get("refresh", "epsilon"),
                                    options.get("outbid_time", "sender"))
    return int(action[0]), int(row[0]), (int(z[0]), float(y[0]), int(t[0])), bool(rebroadcast[0]), i


@pytest.mark.parametrize(("name", "sender", "receiver", "action", "after", "options"), CELLS,
                         ids=[c[0] for c in CELLS])
def test_every_cell_of_table_4_1(name, sender, receiver, action, after, options):
    got, row, record, rebroadcast, i = _run(sender, receiver, options)
    assert (got, tb.ACTION_NAMES[got]) == (action, tb.ACTION_NAMES[action])
    assert row == int(name.split(":")[0])
    if after == "same":
        after = receiver
    z, y, t = after
    if t is None:
        t = T(NOW, i)
    assert record == (z, y, t)
    # the NOTE (line 865-866): only leave & no-rebroadcast stays silent
    assert rebroadcast == (action != tb.LEAVE_QUIET)


def test_the_table_covers_all_32_rows_and_the_default():
    assert {int(c[0].split(":")[0]) for c in CELLS} == set(range(33))


def test_one_vectorised_call_decides_every_cell_like_single_calls():
    """Every cell without options at once: (R, M) = (1, cells) with per-task receivers and senders."""
    plain = [c for c in CELLS if not c[5] or set(c[5]) <= {"receiver", "sender", "outbid_time"}]
    receivers = np.array([c[5].get("receiver", I) for c in plain])
    senders = np.array([c[5].get("sender", K) for c in plain])
    fields = [np.array([[c[1][f] for c in plain]]) for f in range(3)] + \
             [np.array([[c[2][f] for c in plain]]) for f in range(3)]
    action, row = tb.decide(receivers[None, :], senders[None, :], *fields)
    for q, c in enumerate(plain):
        assert action[0, q] == c[3], c[0]
        assert row[0, q] == int(c[0].split(":")[0]), c[0]


WINNERS = {"i": I, "k": K, "m": M, "n": N, "none": E}


@pytest.mark.slow
def test_every_combination_maps_to_exactly_one_action_and_never_adopts_the_receiver_as_winner():
    """All (z_k, z_i) pairs × bid and time orders × options: one action each, from the table's set; the receiver's
    new winner is never itself unless it already was (no row copies z_kj = i, note property 21), and a task the
    receiver held is only lost in rows 1, 2, 17, 18 (outbid) — Johnson §4.2: bundles lose tasks only when outbid."""
    times = (T(8, N), T(10, M), T(12, N))
    for zk, zi in itertools.product(WINNERS.values(), repeat=2):
        if zk == zi and zk in (N,):
            continue
        for yk, yi, tk, ti, guard, refresh, outbid in itertools.product((0.0, 5.0, 6.0), (0.0, 5.0, 6.0), times,
                                                                         times, (True, False), ("epsilon", "now"),
                                                                         ("sender", "bump")):
            yk_, yi_ = (0.0 if zk == E else yk), (0.0 if zi == E else yi)
            args = [np.array([v]) for v in (zk, yk_, tk, zi, yi_, ti)]
            action, row = tb.decide(I, K, *args, row20_guard=guard, row28_guard=guard)
            assert 0 <= action[0] < len(tb.ACTION_NAMES) and 0 <= row[0] <= 32
            z, _, t, _ = tb.apply(action, I, NOW, args[3], args[4], args[5], args[0], args[1], args[2], refresh,
                                  outbid)
            assert z[0] != I or zi == I
            if zi == I and z[0] != I:
                assert row[0] in (1, 2, 17, 18)
            moved = action[0] not in (tb.UPDATE, tb.LEAVE_QUIET, tb.LEAVE, tb.ADOPT_TIME)
            if moved and (action[0] != tb.OUTBID or outbid == "bump"):
                assert t[0] >= ti                      # refreshes and † bumps never move a time backwards


def test_stamps_are_ordered_unique_and_bumps_stay_within_their_tick():
    a, b = stamp(10, 3), stamp(10, 4)
    assert NEVER < stamp(0, 0) < a < b < stamp(11, 0)
    assert a < bump(a, 1) < bump(bump(a, 1), 0) < stamp(11, 0)
    assert (tick_of(bump(a, 7)), bumps_of(bump(a, 7)), stamper_of(bump(a, 7))) == (10, 1, 7)
    assert bump(a, 1) != bump(a, 2)                     # the stamper keeps two agents' bumps apart
    assert tick_of(NEVER) == -1 and NEVER < bump(NEVER, 0) < stamp(0, 0)
    worn = (int(a) >> 40 << 40) | (MAX_BUMPS - 1) << 16
    with pytest.raises(OverflowError):
        bump(np.array([worn]), 0)
