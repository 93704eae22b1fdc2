"""Release actions (``release_actions``, ours): the codec with and without them, the mask cell by cell, a release and
a re-bid, refusals, and random masked play with releases keeping every invariant of ``test_properties``."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pytest
from helpers import agent, build, check_converged_allocation, check_tables, examples, run_episode, task
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_properties import make_env, scenario_config

from taskalloc.policies import CBGAPolicy
from taskalloc.policies.base import Policy
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
    encode_release,
    n_actions,
    quit_columns,
    release_columns,
)
from taskalloc_env.cbba_table import NONE
from taskalloc_env.engine import action_masks, action_masks_reference
from taskalloc_env.errors import InvalidActionError
from taskalloc_env.protocol import ProtocolError
from taskalloc_env.stamps import tick_of


# -- the codec -------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("release", [False, True])
@pytest.mark.parametrize("m", [1, 2, 5, 13])
def test_every_action_round_trips_with_and_without_releases(m, release):
    """1 + 2M actions without the option (pass, bids, quits: the layout unchanged), 1 + 3M with it (the releases
    after the quits); each decodes to one (kind, task) that encodes back to it; the vectorised decoder agrees."""
    assert n_actions(m, release) == 1 + (3 if release else 2) * m and n_actions(m) == 1 + 2 * m
    encoders = {ActionKind.BID: lambda j: encode_bid(j), ActionKind.QUIT: lambda j: encode_quit(j, m),
                ActionKind.RELEASE: lambda j: encode_release(j, m)}
    verbs = {ActionKind.BID: "bid on", ActionKind.QUIT: "quit", ActionKind.RELEASE: "release"}
    seen = set()
    for action in range(n_actions(m, release)):
        kind, task_ = decode(action, m)
        seen.add((kind, task_))
        if kind is ActionKind.PASS:
            assert action == PASS and task_ == -1 and describe(action, m) == "pass"
            continue
        assert 0 <= task_ < m and encoders[kind](task_) == action
        assert describe(action, m) == f"{verbs[kind]} task {task_}"
        assert (kind is ActionKind.RELEASE) == (action > 2 * m)
    assert len(seen) == n_actions(m, release)
    assert release == any(kind is ActionKind.RELEASE for kind, _ in seen)
    actions = np.arange(n_actions(m, release))
    np.testing.assert_array_equal(actions[bid_columns(m)], encode_bid(np.arange(m)))
    np.testing.assert_array_equal(actions[quit_columns(m)], encode_quit(np.arange(m), m))
    np.testing.assert_array_equal(actions[release_columns(m)], encode_release(np.arange(m), m) if release else [])
    kinds, tasks = decode_array(actions.reshape(1, -1), m)
    assert [(ActionKind(k), t) for k, t in zip(kinds[0].tolist(), tasks[0].tolist())] == \
        [decode(a, m) for a in actions.tolist()]


# -- the mask --------------------------------------------------------------------------------------------------------
def test_masks_allow_a_release_exactly_where_the_agent_may_release():
    """``action_masks`` (compiled) and its numpy reference, cell by cell: with ``can_release`` the mask has 1 + 3M
    columns and allows release j iff j is releasable and the agent has not passed; without it, 1 + 2M columns,
    byte-identical to what they were."""
    rng = np.random.default_rng(1)
    for _ in range(30):
        n, m = rng.integers(1, 6, size=2)
        can_bid, can_quit, can_release = (rng.random((n, m)) < 0.5 for _ in range(3))
        passed = rng.random(n) < 0.4
        mask = action_masks(can_bid, can_quit, passed, can_release)
        assert mask.dtype == np.int8 and mask.shape == (n, n_actions(m, True))
        assert mask.tobytes() == action_masks_reference(can_bid, can_quit, passed, can_release).tobytes()
        plain = action_masks(can_bid, can_quit, passed)
        assert plain.shape == (n, n_actions(m)) and plain.tobytes() == mask[:, :n_actions(m)].tobytes()
        assert plain.tobytes() == action_masks_reference(can_bid, can_quit, passed).tobytes()
        for i in range(n):
            assert mask[i, PASS] == 1
            for j in range(m):
                assert mask[i, encode_release(j, m)] == (can_release[i, j] and not passed[i])


@pytest.mark.parametrize("guard", ["none", "exchange", "once"])
@pytest.mark.parametrize("consensus", ["sync", "every_step", "acbba"])
def test_the_env_s_release_columns_are_the_agent_s_bundle_while_it_may_act(consensus, guard):
    """In every step of random masked play the release column of task j is set iff j is in the agent's bundle and the
    agent may act (it has not passed; under ``acbba``, its builder is ready) and, with ``release_guard = exchange``,
    the agent's latest bid on j was made in an earlier round (tick) than now, and with ``once`` it never released j
    (both tracked here from the actions taken); a release zeroes its own bids."""
    env = TaskAllocEnv(n_agents=4, n_tasks=6, agents_per_task=[1, 2], consensus=consensus, release_actions=True,
                       release_guard=guard, invalid_action="raise")
    m = env.config.n_tasks
    assert env.action_space("uav_0").n == 1 + 3 * m
    obs, _ = env.reset(seed=4)
    rng = np.random.default_rng(4)
    seen, guarded = 0, 0
    bid_round, released = np.full((4, m), -1), np.zeros((4, m), dtype=bool)
    while env.agents and env.protocol.round < 12:
        kn, now = env.protocol.knowledge, env.protocol.round
        for a in env.agents:
            i = env.agent_index[a]
            expected = np.zeros(m, dtype=np.int8)
            if not env._engine.passed[i]:
                expected[kn.bundles[i]] = 1
                if guard != "none":
                    held = (bid_round[i] == now) | (released[i] if guard == "once" else False)
                    guarded += int(expected[held].sum())
                    expected[held] = 0
            np.testing.assert_array_equal(obs[a]["action_mask"][release_columns(m)], expected, err_msg=a)
        actions = {a: int(rng.choice(np.flatnonzero(obs[a]["action_mask"]))) for a in env.agents}
        obs, *_ = env.step(actions)
        for a, action in actions.items():
            kind, j = decode(action, m)
            if kind is ActionKind.BID:
                bid_round[env.agent_index[a], j] = now
            if kind is ActionKind.RELEASE:
                seen += 1
                released[env.agent_index[a], j] = True
                assert j not in kn.bundles[env.agent_index[a]] and kn.own_bids()[env.agent_index[a], j] == 0
    assert seen and env.protocol.counters.releases == seen
    # a bid and its release in one round happen only in a synchronous round; a second release anywhere
    assert (guarded > 0) == (guard == "once" or (guard == "exchange" and consensus == "sync")), guarded


# -- a release, a re-bid, refusals -------------------------------------------------------------------------------------
def two_task_line(**overrides: Any) -> TaskAllocEnv:
    """One agent at 0 and tasks at 1, 2 and 3 on a line (L_j = 1), a second agent far away."""
    s = build([agent(0.0), agent(60.0)], [task(1.0), task(2.0), task(3.0)], arena=(100.0, 10.0, 10.0))
    return TaskAllocEnv(s, release_actions=True, invalid_action="raise", dtype="float64", **overrides)


@pytest.mark.parametrize("order", ["bundle", "path"])
def test_a_release_drops_the_task_and_what_follows_it_and_the_task_can_be_bid_again(order):
    """Agent 0 bids tasks 1, 0, 2 (bundle order), then releases task 0: under ``release_order = bundle`` task 0 and
    task 2 (added after it) leave, under ``path`` task 0 and what its path serves after it (1 and 2). Its own bids
    on them are zeroed, the counter counts one release, and bidding task 0 again stores the bid it would store on
    the remaining path."""
    env = two_task_line(release_order=order)
    env.reset(seed=0)
    m = 3
    for j in (1, 0, 2):
        env.step({"uav_0": encode_bid(j), "uav_1": PASS})
    kn = env.protocol.knowledge
    assert kn.bundles[0] == [1, 0, 2] and kn.paths[0] == [0, 1, 2]
    env.step({"uav_0": encode_release(0, m), "uav_1": PASS})
    dropped = {0, 2} if order == "bundle" else {0, 1, 2}
    assert set(kn.bundles[0]) == {0, 1, 2} - dropped and set(kn.paths[0]) == set(kn.bundles[0])
    assert all(kn.groups.bid(0, 0, j) == 0 for j in dropped)
    assert env.protocol.counters.releases == 1 and env.evaluate().summary()["releases"] == 1
    view = env.protocol.view()
    assert view.can_bid[0, 0], "the released task is biddable again"
    expected = float(view.bid[0, 0])
    env.step({"uav_0": encode_bid(0), "uav_1": PASS})
    assert 0 in kn.bundles[0] and kn.groups.bid(0, 0, 0) == expected


def test_a_release_of_a_task_outside_the_bundle_is_refused_naming_agent_action_and_why():
    env = two_task_line()
    env.reset(seed=0)
    env.step({"uav_0": encode_bid(1), "uav_1": PASS})
    with pytest.raises(InvalidActionError, match=r"action 9 \(release task 2\) of uav_0 is not allowed by its "
                                                 r"mask: uav_0 may not release task 2: it is not in its bundle \[1\]"):
        env.step({"uav_0": encode_release(2, 3), "uav_1": PASS})
    with pytest.raises(ProtocolError, match="agent 0 may not release task 2: it is not in its bundle"):
        env.protocol.release(0, 2)


def test_the_exchange_guard_allows_a_release_only_after_the_round_of_the_bid():
    """With ``release_guard = exchange`` a task bid in this round cannot be released (mask 0, a clear refusal from the
    env and from the protocol); once the round has ended (both agents passed) it can; a re-bid in the new round is
    again held until the next exchange. With ``once`` the re-bid task stays held after that exchange too. With
    ``none`` the same release is allowed at once."""
    env = two_task_line(release_guard="exchange")
    env.reset(seed=0)
    obs, *_ = env.step({"uav_0": encode_bid(1), "uav_1": PASS})
    assert obs["uav_0"]["action_mask"][encode_release(1, 3)] == 0
    with pytest.raises(InvalidActionError, match=r"action 8 \(release task 1\) of uav_0 is not allowed by its mask: "
                                                 r"uav_0 may not release task 1: it bid on it in this round \(0\) and "
                                                 r"release_guard = exchange allows a release only after the exchange"):
        env.step({"uav_0": encode_release(1, 3), "uav_1": PASS})
    with pytest.raises(ProtocolError, match=r"agent 0 may not release task 1: it bid on it in this round"):
        env.protocol.release(0, 1)
    obs, *_ = env.step({"uav_0": PASS, "uav_1": PASS})
    assert env.protocol.round == 1 and obs["uav_0"]["action_mask"][encode_release(1, 3)] == 1
    env.step({"uav_0": encode_release(1, 3), "uav_1": PASS})
    obs, *_ = env.step({"uav_0": encode_bid(1), "uav_1": PASS})
    assert 1 in env.protocol.knowledge.bundles[0] and obs["uav_0"]["action_mask"][encode_release(1, 3)] == 0
    once = two_task_line(release_guard="once")
    once.reset(seed=0)
    once.step({"uav_0": encode_bid(1), "uav_1": PASS})
    once.step({"uav_0": PASS, "uav_1": PASS})
    once.step({"uav_0": encode_release(1, 3), "uav_1": PASS})
    once.step({"uav_0": encode_bid(1), "uav_1": PASS})
    obs, *_ = once.step({"uav_0": PASS, "uav_1": PASS})
    assert once.protocol.round == 2 and obs["uav_0"]["action_mask"][encode_release(1, 3)] == 0
    with pytest.raises(ProtocolError, match=r"agent 0 may not release task 1: it released it once already and "
                                            r"release_guard = once allows one release per agent and task"):
        once.protocol.release(0, 1)
    free = two_task_line()
    free.reset(seed=0)
    obs, *_ = free.step({"uav_0": encode_bid(1), "uav_1": PASS})
    assert obs["uav_0"]["action_mask"][encode_release(1, 3)] == 1


class ReleaseFirst(Policy):
    """Release the lowest allowed task, else bid on the lowest biddable one, else pass: the bid–release cycle."""

    name = "release-first"

    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        m = self.n_tasks
        actions = {}
        for a, o in observations.items():
            releases = np.flatnonzero(o["action_mask"][release_columns(m)])
            bids = np.flatnonzero(o["action_mask"][bid_columns(m)])
            actions[a] = int(encode_release(releases[0], m) if releases.size else encode_bid(bids[0]) if bids.size
                             else PASS)
        return actions


@pytest.mark.parametrize("seed", range(3))
def test_the_exchange_guard_ends_every_round_that_release_first_play_would_hold_open(seed):
    """Without the guard an agent that always releases what it just bid never passes, so the first round runs until
    ``max_cycles``; with ``release_guard = exchange`` each round ends within 1 + 5M steps (per agent and round at
    most M releases of earlier bids, 3M bids, M quits); with ``once`` besides, the episode converges after at most
    N · M releases."""
    m = 6
    rounds = {}
    for guard in ("none", "exchange", "once"):
        env = TaskAllocEnv(n_agents=3, n_tasks=m, agents_per_task=[1, 2], release_actions=True, release_guard=guard,
                           max_cycles=300)
        policy = ReleaseFirst()
        obs, infos = env.reset(seed=seed)
        policy.start(env, seed)
        steps_in_round, longest, truncated = 0, 0, False
        while env.agents:
            before = env.protocol.round
            obs, _, _, truncs, infos = env.step(policy.act(obs, infos))
            steps_in_round += 1
            longest = max(longest, steps_in_round)
            if env.protocol.round != before:
                steps_in_round = 0
            truncated = any(truncs.values())
        rounds[guard] = (env.protocol.round, longest, truncated, env.protocol.counters.releases,
                         env.protocol.converged)
    assert rounds["none"][0] == 0 and rounds["none"][1] == 300 and rounds["none"][2], rounds
    assert rounds["exchange"][1] <= 1 + 5 * m and rounds["exchange"][0] > 1 and rounds["exchange"][3] > 0, rounds
    assert rounds["once"][1] <= 1 + 5 * m and 0 < rounds["once"][3] <= 3 * m and rounds["once"][4], rounds


def test_without_the_option_there_is_no_release_action():
    env = TaskAllocEnv(n_agents=2, n_tasks=3, agents_per_task=1, invalid_action="raise")
    env.reset(seed=0)
    assert env.action_space("uav_0").n == 1 + 2 * 3
    with pytest.raises(InvalidActionError, match=r"outside Discrete\(7\)"):
        env.step({"uav_0": encode_release(0, 3), "uav_1": PASS})
    with pytest.raises(ProtocolError, match="release actions need release_actions=True"):
        env.protocol.release(0, 0)


# -- random masked play with releases ----------------------------------------------------------------------------------
class ReleasingThenGreedy(Policy):
    """Random masked play that takes an allowed release with probability ½ for ``rounds`` rounds (ticks), then the
    scripted CBGA (which never releases), so that the episode can converge."""

    name = "releasing"

    def __init__(self, rounds: int, seed: int, task_quitting: bool) -> None:
        super().__init__()
        self.rounds, self.rng = rounds, np.random.default_rng(seed)
        self.finish = CBGAPolicy(task_quitting=task_quitting)

    @property
    def env_overrides(self) -> dict[str, Any]:
        return {"release_actions": True, **self.finish.env_overrides}

    def start(self, env: Any, seed: int | None = None) -> None:
        super().start(env, seed)
        self.finish.start(env, seed)

    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        if self.env.protocol.round >= self.rounds:
            return self.finish.act(observations, infos)
        m = self.n_tasks
        actions = {}
        for a, o in observations.items():
            releases = np.flatnonzero(o["action_mask"][release_columns(m)])
            if releases.size and self.rng.random() < 0.5:
                actions[a] = int(encode_release(int(self.rng.choice(releases)), m))
            else:
                actions[a] = int(self.rng.choice(np.flatnonzero(o["action_mask"])))
        return actions


@settings(max_examples=examples(200), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kw=scenario_config(), seed=st.integers(0, 2**16), rounds=st.integers(1, 4), quitting=st.booleans())
def test_random_play_with_releases_keeps_every_invariant(kw, seed, rounds, quitting):
    """The invariants of ``test_properties`` under random masked play with releases: the table invariants after every
    step (capacity, one winner, self-consistency, bundle = path, feasibility, equipment), and at convergence
    agreement, no conflicts, valid tasks with their equipment and prerequisites, windows, and the return equal to
    ``evaluate().score``."""
    policy = ReleasingThenGreedy(rounds, seed, quitting)
    env = make_env(kw, policy)
    episode = run_episode(env, policy, seed, check=check_tables)
    check_converged_allocation(env, episode)
    assert episode.allocation.agreement


@pytest.mark.parametrize("seed", range(4))
def test_releases_under_acbba_converge_in_agreement(seed):
    """Asynchronously a release goes out as withdrawn entries with the current time (as a quit's do): the run still
    goes quiet conflict-free with every agent holding the same table. (The per-step table checks do not apply: under
    ``acbba`` a bundle keeps a task the listener lost until the builder is ready, Johnson l. 773.)"""
    policy = ReleasingThenGreedy(rounds=15, seed=seed, task_quitting=False)
    env = TaskAllocEnv(n_agents=4, n_tasks=7, agents_per_task=[1, 2], consensus="acbba", **policy.env_overrides)
    episode = run_episode(env, policy, seed)
    check_converged_allocation(env, episode)
    assert env.protocol.counters.releases > 0


def test_an_asynchronous_release_goes_out_as_empty_bids_stamped_now():
    """Under ``acbba`` the released task and the tasks after it become empty bids with the current time in the
    releaser's table, queued for its next broadcast (as a quit's withdrawn entries, Johnson Table 4.1's
    rebroadcast*, l. 866)."""
    env = TaskAllocEnv(n_agents=3, n_tasks=6, agents_per_task=1, consensus="acbba", release_actions=True)
    observations, infos = env.reset(seed=1)
    policy = CBGAPolicy()
    policy.start(env, 1)
    protocol = env.protocol
    kn = protocol.knowledge
    while not any(len(kn.bundles[i]) > 1 and protocol.ready[i] for i in range(3)):
        observations, *_, infos = env.step(policy.act(observations, infos))
    i = next(i for i in range(3) if len(kn.bundles[i]) > 1 and protocol.ready[i])
    protocol.outgoing[i] = False
    first = kn.bundles[i][0]
    released = [first, *protocol.release(i, first)]
    assert len(released) > 1 and not kn.bundles[i]
    for j in released:
        assert tick_of(protocol.times.task[i, j]) == protocol.round and protocol.outgoing[i, j]
        assert kn.winner[i, j] == NONE


def test_a_learned_policy_refuses_an_environment_with_release_actions():
    """The committed actors have the heads of the 1 + 2M layout (``kinds=2``); a release layout is refused before any
    step (``tests/test_learned_release.py``: actors with release heads)."""
    from taskalloc.policies import make_policy

    policy = make_policy("learned:train_small")
    env = TaskAllocEnv("train_small", release_actions=True, **policy.env_overrides)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"1 \+ 2M layout .* has release actions: build it without release_actions"):
        policy.start(env, 0)


@pytest.mark.parametrize("guard", ["none", "exchange", "once"])
def test_the_compiled_release_options_equal_their_numpy_reference(guard):
    """``kernels.quits.releasable`` (what ``release_options`` and the arrays engine use) and
    ``Protocol.releasable_reference`` agree at every step of random masked play, and both allow releases."""
    env = TaskAllocEnv(n_agents=4, n_tasks=6, agents_per_task=[1, 2], release_actions=True, release_guard=guard,
                       task_quitting=True)
    rng = np.random.default_rng(3)
    allowed = 0
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        while env.agents and env.protocol.round < 10:
            compiled = env.protocol.release_options()
            np.testing.assert_array_equal(compiled, env.protocol.releasable_reference())
            allowed += int(compiled.sum())
            obs, *_ = env.step({a: int(rng.choice(np.flatnonzero(o["action_mask"]))) for a, o in obs.items()})
    assert allowed > 0
