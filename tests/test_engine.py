"""The action codec (``taskalloc_env.actions``) and the step engine (``taskalloc_env.engine``): every action round-trips
cell by cell, the masks follow the rule the observation documents, and the env and the direct solver step alike."""

from __future__ import annotations

import numpy as np
import pytest

from taskalloc_env import TaskAllocEnv
from taskalloc_env.actions import (
    PASS,
    ActionKind,
    bid_columns,
    decode,
    decode_array,
    describe,
    encode_bid,
    encode_quit,
    n_actions,
    quit_columns,
)
from taskalloc_env.engine import StepEngine, action_masks, action_masks_reference


@pytest.mark.parametrize("m", [1, 2, 5, 13])
def test_every_action_round_trips(m):
    """Each of the 1 + 2M actions decodes to one (kind, task) that encodes back to it; the columns of a kind hold
    its tasks in order; the vectorised decoder agrees cell by cell."""
    seen = set()
    for action in range(n_actions(m)):
        kind, task = decode(action, m)
        seen.add((kind, task))
        if kind is ActionKind.PASS:
            assert action == PASS and task == -1 and describe(action, m) == "pass"
        elif kind is ActionKind.BID:
            assert 0 <= task < m and encode_bid(task) == action and describe(action, m) == f"bid on task {task}"
        else:
            assert 0 <= task < m and encode_quit(task, m) == action and describe(action, m) == f"quit task {task}"
    assert len(seen) == n_actions(m)
    actions = np.arange(n_actions(m))
    np.testing.assert_array_equal(actions[bid_columns(m)], encode_bid(np.arange(m)))
    np.testing.assert_array_equal(actions[quit_columns(m)], encode_quit(np.arange(m), m))
    kinds, tasks = decode_array(actions.reshape(1, -1), m)
    assert kinds.shape == tasks.shape == (1, n_actions(m))
    assert [(ActionKind(k), t) for k, t in zip(kinds[0].tolist(), tasks[0].tolist())] == \
        [decode(a, m) for a in actions.tolist()]


def test_masks_allow_pass_and_only_an_acting_agent_s_bids_and_quits():
    """``action_masks`` (compiled) and its numpy reference, cell by cell: pass always; bid j iff the bid is valid
    and the agent has not passed; quit j iff the quit is allowed and the agent has not passed."""
    rng = np.random.default_rng(0)
    for _ in range(20):
        n, m = rng.integers(1, 6, size=2)
        can_bid, can_quit, passed = rng.random((n, m)) < 0.5, rng.random((n, m)) < 0.5, rng.random(n) < 0.4
        mask = action_masks(can_bid, can_quit, passed)
        assert mask.dtype == np.int8 and mask.shape == (n, n_actions(m))
        assert mask.tobytes() == action_masks_reference(can_bid, can_quit, passed).tobytes(), "kernel = reference"
        for i in range(n):
            assert mask[i, PASS] == 1
            for j in range(m):
                assert mask[i, encode_bid(j)] == (can_bid[i, j] and not passed[i])
                assert mask[i, encode_quit(j, m)] == (can_quit[i, j] and not passed[i])


@pytest.mark.parametrize("consensus", ["sync", "every_step", "acbba"])
def test_the_env_hands_out_the_engine_s_masks_and_steps_through_it(consensus):
    """The env's masks are the engine's, and a step the env takes is the engine's step: a second engine on a copy of
    the protocol, given the same decisions, reaches the same tables, round and masks."""
    import copy

    env = TaskAllocEnv(n_agents=4, n_tasks=6, agents_per_task=[1, 2], consensus=consensus, task_quitting=True,
                       delta=0)
    obs, _ = env.reset(seed=3)
    rng = np.random.default_rng(3)
    while env.agents:
        engine = StepEngine(copy.deepcopy(env.protocol))
        engine.passed = env._engine.passed.copy()
        engine.steps = env._engine.steps
        for a in env.agents:
            np.testing.assert_array_equal(obs[a]["action_mask"], engine.masks()[env.agent_index[a]])
        actions = {a: int(rng.choice(np.flatnonzero(obs[a]["action_mask"]))) for a in env.agents}
        engine.apply((env.agent_index[a], action) for a, action in actions.items())
        obs, *_ = env.step(actions)
        assert engine.protocol.round == env.protocol.round
        assert engine.protocol.knowledge.groups == env.protocol.knowledge.groups
        np.testing.assert_array_equal(engine.passed, env._engine.passed)


@pytest.mark.parametrize("consensus", ["sync", "every_step", "acbba"])
def test_a_round_ends_when_its_consensus_mode_says(consensus):
    """``sync``: the round ends once every agent has passed, and a passed agent may only pass until then (thesis
    §3.2.2–3.2.3); ``every_step``: after every step; ``acbba``: every step is one tick (Johnson §4.1)."""
    env = TaskAllocEnv(n_agents=3, n_tasks=6, agents_per_task=1, consensus=consensus)
    env.reset(seed=2)
    engine = env._engine
    if consensus == "acbba":                # no builder is ready at tick 0 (build_ticks ≥ 1): everyone passes
        for tick in (1, 2):
            engine.apply([(i, PASS) for i in range(3)])
            assert env.protocol.round == engine.steps == tick
        return
    bidder = int(engine.acting()[0])
    bids = np.flatnonzero(engine.masks()[bidder, bid_columns(6)])
    assert bids.size, "the first acting agent has a bid"
    engine.apply([(i, encode_bid(int(bids[0])) if i == bidder else PASS) for i in engine.acting().tolist()])
    if consensus == "sync":
        assert env.protocol.round == 0 and engine.passed.sum() == 2 and not engine.passed[bidder]
        assert engine.masks()[engine.passed, 1:].sum() == 0, "a passed agent may only pass"
        engine.apply([(bidder, PASS)])
    assert env.protocol.round == 1 and engine.steps == (2 if consensus == "sync" else 1)
    assert not engine.passed.any(), "a new round: every live agent may act again"
