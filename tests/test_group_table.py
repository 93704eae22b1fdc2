"""The sparse group table against the dense matrices X_i[k][j] it stands for (``group_table.GroupTable``)."""

from __future__ import annotations

import numpy as np
import pytest

from taskalloc_env.group_table import GroupOverflow, GroupTable


def random_table(rng: np.random.Generator, n: int, capacity: np.ndarray, writes: int) -> GroupTable:
    """A table after ``writes`` random bids and withdrawals, each kept within L_j."""
    table = GroupTable.empty(n, n, capacity)
    for _ in range(writes):
        i, k, j = int(rng.integers(n)), int(rng.integers(n)), int(rng.integers(len(capacity)))
        value = float(rng.choice([0.0, rng.uniform(1, 9)]))
        if value > 0 and table.bid(i, k, j) == 0 and table.count[i, j] >= capacity[j]:
            continue
        table.set(i, k, j, value)
    return table


def dense(table: GroupTable) -> np.ndarray:
    return np.stack([table.dense(i) for i in range(table.n_agents)])          # (holder, agent, task)


@pytest.mark.parametrize("seed", range(12))
def test_joined_and_changed_match_the_dense_matrices(seed):
    rng = np.random.default_rng(seed)
    n, capacity = 5, rng.integers(1, 5, size=7)
    before = random_table(rng, n, capacity, 60)
    after = before.copy()
    for _ in range(15):                                     # a few more writes on a copy
        i, k, j = int(rng.integers(n)), int(rng.integers(n)), int(rng.integers(len(capacity)))
        if after.count[i, j] < capacity[j] or after.bid(i, k, j) > 0:
            after.set(i, k, j, float(rng.choice([0.0, rng.uniform(1, 9)])))
    old, new = dense(before), dense(after)
    assert np.array_equal(after.joined(before), ((new > 0) & (old <= 0)).any(axis=1))
    assert np.array_equal(after.changed(before), (new != old).any(axis=1))
    assert np.array_equal(after.own_bids(), np.einsum("iij->ij", new))
    assert (after == before) == np.array_equal(new, old)


def test_a_write_beyond_the_group_size_is_refused():
    table = GroupTable.empty(3, 3, np.array([2]))
    table.set(0, 0, 0, 5.0)
    table.set(0, 2, 0, 4.0)
    with pytest.raises(GroupOverflow, match="member 3 of task 0's group in agent 0's table"):
        table.set(0, 1, 0, 3.0)
    assert table.members[0, 0].tolist() == [0, 2] and table.bids[0, 0].tolist() == [5.0, 4.0]


def test_a_single_agent_column_holds_one_member():
    table = GroupTable.empty(2, 2, np.array([1, 3]))
    table.set(0, 1, 0, 5.0)
    with pytest.raises(GroupOverflow, match="member 2 of task 0's group in agent 0's table"):
        table.set(0, 0, 0, 6.0)
    table.set(0, 1, 0, 0.0)
    table.set(0, 0, 0, 6.0)
    assert (table.members[0, 0, 0], table.bids[0, 0, 0], table.count[0, 0], table.own[0, 0]) == (0, 6.0, 1, 6.0)
