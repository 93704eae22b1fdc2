"""The CBBA decision table for single-agent tasks (Choi et al. 2009; Johnson §3.4.1 Table 3.1; thesis Table 2.1).

Every cell of the table is one parametrised case below. Inside a case, every combination of the conditions the
table can read is enumerated: the sender's timestamp for the agent it believes in (m) newer / equal / older than the
receiver's, the same for the receiver's third agent (n), and the sender's bid higher / equal / lower than the
receiver's (equal bids go to the higher winner id, thesis §3.2.3 and App. A.1). The expected action is written
from Johnson's Table 3.1; ``decide`` is called once vectorised over all combinations and once per combination.

Agent ids: receiver i = 1, sender k = 2, third agents m = 3 and n = 4 (agent 0 exists but is never named), so a tie
between (k, m) goes to m and a tie between (k, i) or (m, i) goes to the sender's winner.
"""

from __future__ import annotations

import itertools
from types import SimpleNamespace

import numpy as np
import pytest

from taskalloc_env.cbba_table import LEAVE, NONE, RESET, UPDATE, decide, outbids

I_ID, K_ID, M_ID, N_ID = 1, 2, 3, 4
N_AGENTS = 5
NAMES = {LEAVE: "leave", UPDATE: "update", RESET: "reset"}
TIMES = {"newer": 1.0, "equal": 0.0, "older": -1.0}     # sender's stamp minus receiver's stamp
BIDS = {"higher": 10.0, "equal": 0.0, "lower": -10.0}    # sender's bid minus receiver's bid


def _winner(belief: str, sender_belief: str) -> int:
    """Agent id of a belief; the receiver's third agent is m unless the sender already believes m (then n)."""
    if belief == "none":
        return NONE
    if belief == "third":
        return N_ID if sender_belief == "m" else M_ID
    return {"i": I_ID, "k": K_ID, "m": M_ID, "n": N_ID}[belief]


def _update(c):
    return UPDATE


def _leave(c):
    return LEAVE


def _reset(c):
    return RESET


# (sender believes, receiver believes, rule of Johnson §3.4.1 Table 3.1, the rule as that table prints it).
# c.better: y_k ≻ y_i; c.fresh_m / c.stale_m: s_k[m] > s_i[m] / s_i[m] > s_k[m] for the sender's winner m;
# c.fresh_n: s_k[n] > s_i[n] for the receiver's winner n (written "m" in the rows where the sender believes k, i
# or none, because there the receiver's third agent is the only third agent).
CANONICAL = [
    ("k", "i", lambda c: UPDATE if c.better else LEAVE, "update if y_k ≻ y_i"),
    ("k", "k", _update, "update"),
    ("k", "third", lambda c: UPDATE if c.fresh_n or c.better else LEAVE, "update if s_k[m] > s_i[m] or y_k ≻ y_i"),
    ("k", "none", _update, "update"),
    ("i", "i", _leave, "leave"),
    ("i", "k", _reset, "reset"),
    ("i", "third", lambda c: RESET if c.fresh_n else LEAVE, "reset if s_k[m] > s_i[m]"),
    ("i", "none", _leave, "leave"),
    ("m", "i", lambda c: UPDATE if c.fresh_m and c.better else LEAVE, "update if s_k[m] > s_i[m] and y_k ≻ y_i"),
    ("m", "k", lambda c: UPDATE if c.fresh_m else RESET, "update if s_k[m] > s_i[m], else reset"),
    ("m", "m", lambda c: UPDATE if c.fresh_m else LEAVE, "update if s_k[m] > s_i[m]"),
    ("m", "third",
     lambda c: UPDATE if (c.fresh_m and c.fresh_n) or (c.fresh_m and c.better)
     else RESET if (c.fresh_n and c.stale_m) else LEAVE,
     "update if s_k[m]>s_i[m] and s_k[n]>s_i[n]; update if s_k[m]>s_i[m] and y_k ≻ y_i; "
     "reset if s_k[n]>s_i[n] and s_i[m]>s_k[m]"),
    ("m", "none", lambda c: UPDATE if c.fresh_m else LEAVE, "update if s_k[m] > s_i[m]"),
    ("none", "i", _leave, "leave"),
    ("none", "k", _update, "update"),
    ("none", "third", lambda c: UPDATE if c.fresh_n else LEAVE, "update if s_k[m] > s_i[m]"),
    ("none", "none", _leave, "leave"),
]

# The thesis transcription (thesis §2.2.4, Table 2.1) differs in exactly two cells.
THESIS_DIFF = {
    ("i", "third"): (_leave, "leave (the thesis prints 'if s_km > s_im → leave')"),
    ("m", "i"): (lambda c: UPDATE if c.fresh_m or c.better else LEAVE, "update if s_k[m] > s_i[m] or y_k ≻ y_i"),
}
THESIS = [(s, r, *THESIS_DIFF.get((s, r), (rule, text))) for s, r, rule, text in CANONICAL]


def _cases(sender_belief: str, receiver_belief: str):
    """Every combination of the conditions for one cell: arrays for decide() plus the readable conditions."""
    z_k = _winner(sender_belief, sender_belief)
    z_i = _winner(receiver_belief, sender_belief)
    rows = []
    for (tm_name, tm), (tn_name, tn), (bid_name, db) in itertools.product(TIMES.items(), TIMES.items(),
                                                                         BIDS.items()):
        s_i = np.full(N_AGENTS, 5.0)
        s_k = np.full(N_AGENTS, 5.0)
        s_k[K_ID] = 7.0                      # a real sender always has the freshest stamp of itself
        s_i[K_ID] = 6.0
        s_k[M_ID] += tm
        s_k[N_ID] += tn
        y_i = 0.0 if z_i == NONE else 50.0
        y_k = 0.0 if z_k == NONE else 50.0 + db
        # the receiver's third agent is M_ID, or N_ID when the sender already believes M_ID
        third = z_i if z_i not in (I_ID, K_ID, NONE) else None
        fresh_n = third is not None and s_k[third] > s_i[third]
        fresh_m = z_k not in (I_ID, K_ID, NONE) and s_k[z_k] > s_i[z_k]
        stale_m = z_k not in (I_ID, K_ID, NONE) and s_i[z_k] > s_k[z_k]
        better = bool(outbids(np.float64(y_k), np.int64(z_k), np.float64(y_i), np.int64(z_i)))
        cond = SimpleNamespace(fresh_m=fresh_m, stale_m=stale_m, fresh_n=fresh_n, better=better,
                               label=f"s[m] {tm_name}, s[n] {tn_name}, bid {bid_name}")
        rows.append((z_i, y_i, z_k, y_k, s_i, s_k, cond))
    return rows


@pytest.mark.parametrize("table, sender_belief, receiver_belief, rule, text", [
    pytest.param(name, s, r, rule, text, id=f"{name}: sender {s} | receiver {r} -> {text}")
    for name, rows in (("canonical", CANONICAL), ("thesis", THESIS)) for s, r, rule, text in rows
])
def test_cbba_table_cell(table, sender_belief, receiver_belief, rule, text):
    cases = _cases(sender_belief, receiver_belief)
    z_i = np.array([[c[0]] for c in cases])
    y_i = np.array([[c[1]] for c in cases])
    z_k = np.array([[c[2]] for c in cases])
    y_k = np.array([[c[3]] for c in cases])
    s_i = np.array([c[4] for c in cases])
    s_k = np.array([c[5] for c in cases])
    vectorised = decide(np.full(len(cases), I_ID), np.full(len(cases), K_ID), z_i, y_i, z_k, y_k, s_i, s_k, table=table)
    assert vectorised.shape == (len(cases), 1)
    for row, (zi, yi, zk, yk, si, sk, cond) in enumerate(cases):
        expected = rule(cond)
        single = decide(I_ID, K_ID, np.array([zi]), np.array([yi]), np.array([zk]), np.array([yk]), si, sk, table=table)
        assert NAMES[int(single[0])] == NAMES[expected], f"{text} [{cond.label}]"
        assert NAMES[int(vectorised[row, 0])] == NAMES[expected], f"vectorised: {text} [{cond.label}]"


@pytest.mark.parametrize("table, rows", [("canonical", CANONICAL), ("thesis", THESIS)])
def test_every_pair_of_winner_ids_follows_its_cell(table, rows):
    """Table completeness: each (sender's winner, receiver's winner) pair of *actual ids* — every agent 0..4 or none,
    third agents on either side of i and k in id order — is decided by the one cell that names the pair's roles."""
    rule = {(s, r): f for s, r, f, _ in rows}
    role = {I_ID: "i", K_ID: "k"}
    for z_k, z_i in itertools.product([NONE, *range(N_AGENTS)], repeat=2):
        sender = "none" if z_k == NONE else role.get(z_k, "m")
        receiver = "none" if z_i == NONE else role.get(z_i, "m" if z_i == z_k else "third")
        for (tk_name, tk), (ti_name, ti), (bid_name, db) in itertools.product(TIMES.items(), TIMES.items(),
                                                                             BIDS.items()):
            s_i = np.full(N_AGENTS, 5.0)
            s_k = np.full(N_AGENTS, 5.0)
            s_k[K_ID], s_i[K_ID] = 7.0, 6.0
            if z_k not in (NONE, I_ID, K_ID):
                s_k[z_k] += tk
            if z_i not in (NONE, I_ID, K_ID, z_k):
                s_k[z_i] += ti
            y_i = 0.0 if z_i == NONE else 50.0
            y_k = 0.0 if z_k == NONE else 50.0 + db
            third_k = z_k not in (NONE, I_ID, K_ID)
            third_i = z_i not in (NONE, I_ID, K_ID)
            cond = SimpleNamespace(fresh_m=third_k and s_k[z_k] > s_i[z_k], stale_m=third_k and s_i[z_k] > s_k[z_k],
                                   fresh_n=third_i and s_k[z_i] > s_i[z_i],
                                   better=bool(outbids(np.float64(y_k), np.int64(z_k), np.float64(y_i),
                                                       np.int64(z_i))))
            got = decide(I_ID, K_ID, np.array([z_i]), np.array([y_i]), np.array([z_k]), np.array([y_k]), s_i, s_k,
                         table=table)
            want = rule[(sender, receiver)](cond)
            assert NAMES[int(got[0])] == NAMES[want], (
                f"sender believes {z_k} ({sender}), receiver {z_i} ({receiver}); s[z_k] {tk_name}, s[z_i] {ti_name}, "
                f"bid {bid_name}")


def test_whole_message_is_decided_per_task():
    """One message over many tasks: each task column follows its own cell (vectorised over the task axis)."""
    s_i = np.array([0.0, 3.0, 4.0, 2.0, 6.0])
    s_k = np.array([0.0, 2.0, 5.0, 4.0, 1.0])   # sender fresher about m = 3, staler about n = 4
    #            k|i   k|k  i|k   m|k   m|n   none|k none|n  m|i
    z_k = np.array([K_ID, K_ID, I_ID, M_ID, M_ID, NONE, NONE, M_ID])
    y_k = np.array([60.0, 40.0, 30.0, 45.0, 45.0, 0.0, 0.0, 40.0])
    z_i = np.array([I_ID, K_ID, K_ID, K_ID, N_ID, K_ID, N_ID, I_ID])
    y_i = np.array([50.0, 30.0, 20.0, 20.0, 90.0, 10.0, 10.0, 50.0])
    got = decide(I_ID, K_ID, z_i, y_i, z_k, y_k, s_i, s_k)
    # k|i: 60 > 50 update; k|k update; i|k reset; m|k: s_k[m] 4 > 2 update; m|n: fresh m, stale n, lower bid: leave
    # none|k update; none|n: s_k[n] 1 < 6 leave; m|i: fresh m but 40 < 50: leave
    assert [NAMES[int(a)] for a in got] == ["update", "update", "reset", "update", "leave", "update", "leave",
                                            "leave"]


def test_decide_broadcasts_over_receivers():
    """A leading receiver axis: one call decides the same message for several receivers."""
    z_k = np.array([[2, 2], [2, 2]])
    y_k = np.array([[50.0, 50.0], [50.0, 50.0]])
    z_i = np.array([[0, NONE], [3, NONE]])
    y_i = np.array([[50.0, 0.0], [50.0, 0.0]])
    s = np.zeros((2, 5))
    got = decide(np.array([0, 3]), np.array([2, 2]), z_i, y_i, z_k, y_k, s, s)
    # receiver 0 believes itself, tie 50/50 → higher id k=2 wins → update; receiver 3 believes itself, (50, 2) vs
    # (50, 3) → receiver keeps it
    assert got.tolist() == [[UPDATE, UPDATE], [LEAVE, UPDATE]]


@pytest.mark.parametrize("a, ida, b, idb, expected", [
    (60.0, 1, 50.0, 9, True),      # higher bid wins whatever the ids
    (50.0, 9, 60.0, 1, False),
    (50.0, 4, 50.0, 3, True),      # equal bids: the higher id wins (thesis §3.2.3)
    (50.0, 3, 50.0, 4, False),
    (50.0, 3, 50.0, 3, False),     # not strictly better than itself
])
def test_outbids_is_lexicographic_on_bid_then_id(a, ida, b, idb, expected):
    assert bool(outbids(np.float64(a), np.int64(ida), np.float64(b), np.int64(idb))) is expected
