"""One admission rule for the bid mask and the consensus merge (thesis Alg 5 l. 8–20; Alg 6 l. 13–23, (3.15)).

Agent i's bid mask says whether i may join column j of its own table (and whom it displaces). When i then bids and
sends its table to a receiver that holds the same column as i did before the bid, the merge must reach the same
verdict: the receiver ends with i's new column if the mask accepted the bid, and with its old column otherwise.
Random tables, bids, equipment and L_j drive both sides.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from helpers import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from taskalloc_env import kernels
from taskalloc_env.bidding import bid_view, refresh_rows
from taskalloc_env.cbba_table import NONE
from taskalloc_env.group_merge import merge
from taskalloc_env.groups import Equipment
from taskalloc_env.knowledge import LocalKnowledge
from taskalloc_env.scenario import Agent, Scenario, Task

BID_VALUES = st.sampled_from([0.0, 10.0, 20.0, 30.0, 30.0, 40.0])      # repeats make exact ties common


@st.composite
def tables(draw):
    """A scenario of N agents and M multi-agent tasks, agent i's table before a bid, and i's gains."""
    n = draw(st.integers(3, 6))
    m = draw(st.integers(1, 4))
    typed = draw(st.booleans())
    types = [draw(st.sampled_from("AB")) for _ in range(n)] if typed else [None] * n
    agents = [Agent((float(k % 3), float(k // 3), 0.0), 1.0, () if t is None else (t,)) for k, t in enumerate(types)]
    tasks = []
    for _ in range(m):
        need = draw(st.integers(2, 3))
        equipment = tuple(draw(st.sampled_from("AB")) for _ in range(need)) if typed and draw(st.booleans()) else ()
        tasks.append(Task((1.0, 1.0, 0.0), 100.0, 0.0, 50.0, 1.0, agents=need, equipment=equipment))
    scenario = Scenario.from_entities(agents, tasks, equipment_names=("A", "B") if typed else ())
    i = draw(st.integers(0, n - 1))
    table = np.array([[draw(BID_VALUES) for _ in range(m)] for _ in range(n)])
    table[i] = 0.0                                                   # i is not a member yet
    for j in range(m):                                               # at most L_j members per column
        holders = np.flatnonzero(table[:, j] > 0)
        table[holders[scenario.task_agents[j]:], j] = 0.0
    gains = np.array([draw(st.sampled_from([5.0, 20.0, 30.0, 45.0])) for _ in range(m)])
    return scenario, i, table, gains


@pytest.mark.filterwarnings("ignore:tasks .* are identical")     # identical tasks are drawn on purpose
@pytest.mark.parametrize("mask", ["reference", "compiled"])
@pytest.mark.parametrize("outbid_ties", ["higher_id", "strict"])
@settings(max_examples=examples(300), deadline=None)
@given(tables(), st.data())
def test_bid_mask_and_merge_admit_the_same_bids(mask, outbid_ties, case, data):
    """Under ``higher_id`` the mask and the merge decide every bid alike; under ``strict`` (the bundle phase's ">")
    the mask refuses exactly the bids that would displace a member with an equal bid, which the merge's (bid, id)
    order would admit. The mask comes from ``bid_view`` (numpy) or from the compiled kernel the protocol runs
    (``refresh_rows``), each against the numpy merge (the compiled merge equals it: tests/test_kernels.py)."""
    if mask == "compiled" and not kernels.COMPILED:
        pytest.skip("numba is not installed")
    scenario, i, table, gains = case
    n, m = table.shape
    receiver = data.draw(st.sampled_from([k for k in range(n) if k != i]))
    equipment = Equipment(scenario.agent_equipment, scenario.task_equipment)
    knowledge = LocalKnowledge.empty(n, m, scenario.task_agents, know_everyone=True)
    knowledge.groups.set_columns(np.array([i]), np.arange(m), table[None])
    gain = np.zeros((n, m))
    gain[i] = gains
    build = bid_view if mask == "reference" else functools.partial(refresh_rows, None, range(n))
    view = build(knowledge, scenario, equipment, scenario.eligible(), gain, np.zeros((n, m), dtype=np.int64),
                 prereq_mode="all_have_bid", require_known_capacity=False, max_bundle=m,
                 fillable=np.ones(m, dtype=bool), bid_warping=False, outbid_ties=outbid_ties)
    # i bids on every task at once (columns are independent): its table after the bids, as Protocol.bid writes it
    after = table.copy()
    for j in range(m):
        if view.outbid[i, j]:
            if view.displaced[i, j] != NONE:
                assert after[view.displaced[i, j], j] == view.displaced_bid[i, j]
                after[view.displaced[i, j], j] = 0.0
            after[i, j] = gains[j]
    # the receiver holds i's old table; i is the sender (trusted on its own row), other stamps are equal
    s_i = np.full((1, n), 5.0)
    s_k = s_i.copy()
    s_k[0, i] = 6.0
    sent = np.where(np.arange(n)[:, None] == i, gains[None, :], table)     # every bid offered, accepted or not
    merged = merge(table[None].copy(), sent[None], np.array([receiver]), np.array([i]), s_i, s_k,
                   scenario.task_agents, equipment)[0]
    for j in range(m):
        admitted = not np.array_equal(merged[:, j], table[:, j])
        if view.outbid[i, j]:
            np.testing.assert_array_equal(merged[:, j], after[:, j], err_msg=f"task {j}: the mask admits the bid")
        elif admitted:                 # only a tie the bundle phase refuses (strict) may differ
            assert outbid_ties == "strict", f"task {j}: the merge admits a bid the mask refuses"
            assert gains[j] in table[:, j], f"task {j}: the merge admits a bid that ties no member"
