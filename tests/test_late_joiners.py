"""Late joiners (``join_at``): absent from ``env.agents`` until their round, neither sending nor receiving before it,
knowing nothing but what they hear after; every policy runs with them; bad input is one line."""

from __future__ import annotations

import re

import numpy as np
import pytest
from helpers import agent, build, episode_digest, task

from taskalloc.policies import make_policy, rollout
from taskalloc.policies.fast import solve as fast_solve
from taskalloc_env import ConfigError, TaskAllocConfig, TaskAllocEnv, resolve_config
from taskalloc_env.protocol import Protocol
from taskalloc_env.scenario import generate

JOINS = {1: 3, 3: 6}


def step_until(env: TaskAllocEnv, policy, obs, infos, stop):
    """Step ``env`` with ``policy`` until ``stop(env)`` holds or the episode ends; returns the last outputs."""
    while env.agents and not stop(env):
        live = env.agents
        obs, _, _, _, infos = env.step(policy.act({a: obs[a] for a in live}, {a: infos[a] for a in live}))
    return obs, infos


@pytest.mark.parametrize("consensus", ["sync", "acbba"])
def test_a_joiner_is_absent_silent_and_deaf_until_its_round_then_hears_its_neighbours(consensus):
    policy = make_policy("cbga")
    env = TaskAllocEnv("train_small", join_at={1: 8, 3: 12}, consensus=consensus)
    obs, infos = env.reset(seed=0)
    policy.start(env, 0)
    p = env.protocol
    assert env.agents == ["uav_0", "uav_2"] and set(obs) == set(infos) == {"uav_0", "uav_2"}
    obs, infos = step_until(env, policy, obs, infos, lambda e: e.protocol.round >= 7)
    assert p.round == 7 and "uav_1" not in env.agents and "uav_1" not in obs
    assert p.network.sent_by[[1, 3]].tolist() == [0, 0]                  # sent nothing
    heard = p.knowledge.timestamps * (1 - np.eye(4, dtype=np.int64))       # s_i[k]: when i last heard of k
    assert heard[[1, 3]].max() == 0 and p.counters.messages > 0        # received nothing, while others talk
    assert not p.knowledge.groups.listed()[[1, 3]].any() and p.knowledge.bundles[1] == []   # knows no bid
    obs, infos = step_until(env, policy, obs, infos, lambda e: e.protocol.round >= 8)
    assert "uav_1" in env.agents and "uav_1" in obs and "uav_1" in infos and "uav_3" not in env.agents
    obs, infos = step_until(env, policy, obs, infos, lambda e: e.protocol.round >= 11)
    assert np.delete(p.knowledge.timestamps[1], 1).max() > 0
    assert p.network.sent_by[1] > 0 or consensus == "acbba"          # an ACBBA agent sends only what changed
    assert p.knowledge.groups.listed()[1].any()                         # it heard the others' bids
    step_until(env, policy, obs, infos, lambda e: False)
    allocation = env.evaluate()
    assert allocation.converged and allocation.agreement


POLICIES = [("random", {}), ("cbga", {}), ("cbga+tq", {}), ("cbga+tb", {}), ("cbgabi", {}),
            ("cbba", {"agents_per_task": 1}), ("acbba", {"agents_per_task": 1}), ("cbga", {"consensus": "acbba"}),
            ("cbgabi", {"consensus": "every_step"}), ("cbga", {"message_loss": 0.2}),
            ("acbba", {"agents_per_task": 1, "message_loss": 0.2})]


@pytest.mark.parametrize("policy, overrides", POLICIES, ids=[f"{p}-{'-'.join(o) or 'sync'}" for p, o in POLICIES])
def test_every_policy_runs_with_late_joiners_and_the_team_agrees(policy, overrides):
    p = make_policy(policy)
    env = TaskAllocEnv("train_small", join_at=JOINS, **overrides, **p.env_overrides)
    flown = 0
    for seed in range(8):
        allocation = rollout(env, p, seed=seed)
        assert allocation.converged and allocation.agreement and not allocation.conflicts, f"seed {seed}"
        assert allocation.counters.invalid_actions == 0
        flown += len(allocation.paths[1]) + len(allocation.paths[3])
    assert flown > 0                                                     # the joiners take part


def test_an_acbba_joiner_that_bids_on_nothing_still_learns_every_record():
    """Agent 2 joins after the others agreed, too far from every task to bid (γ = 10 per km). ACBBA sends only
    changes, so it learns the records from its neighbours' announcement on its arrival, and the team agrees."""
    s = build([agent(0), agent(1), agent(9, 9)], [task(0, 1), task(1, 1), task(2, 1)])
    p = make_policy("acbba")
    env = TaskAllocEnv(scenario=s, join_at={2: 20}, **p.env_overrides)
    allocation = rollout(env, p, seed=0)
    assert allocation.paths[2] == () and all(allocation.members[j] for j in range(3))
    assert allocation.converged and allocation.agreement
    assert env.protocol.knowledge.groups.listed()[2].any()


def test_a_late_join_holds_the_stop_until_the_joiner_is_in():
    """Without joiners CBGA agrees within a few rounds; with one at round 30 the run goes on until it has joined and
    the team has agreed again."""
    p = make_policy("cbga")
    early = rollout(TaskAllocEnv("train_small"), p, seed=1)
    late = rollout(TaskAllocEnv("train_small", join_at={2: 30}), p, seed=1)
    assert early.counters.rounds < 30 < late.counters.rounds and late.converged and late.agreement


def test_the_direct_solver_reaches_the_episodes_allocation():
    cfg = resolve_config(n_agents=5, n_tasks=8, agents_per_task=[1, 2], join_at={0: 2, 4: 5})
    policy = make_policy("cbgabi")
    env = TaskAllocEnv(cfg, **policy.env_overrides)
    for seed in range(3):
        episode = rollout(env, policy, seed=seed)
        assert fast_solve(env.scenario, cfg, "cbgabi") == episode


def test_a_joiner_that_fails_first_never_joins():
    cfg = resolve_config(n_agents=3, n_tasks=4, agents_per_task=1, join_at={1: 5})
    p = Protocol(generate(cfg, np.random.default_rng(0)), cfg)
    assert p.joins == {5: (1,)} and not p.alive[1] and p.joins_ahead
    p._fail_agents((1,))
    assert p._join_agents((1,)) == [] and not p.alive[1] and not p.joins_ahead


def test_late_joiners_replay_from_the_seed():
    runs = [episode_digest(("cbgabi", {"join_at": JOINS}, seed)) for seed in (4, 4, 5)]
    assert runs[0] == runs[1] != runs[2]


@pytest.mark.parametrize("join_at, words", [
    ({7: 3}, "'join_at': got 7; allowed: an agent id 0..3"),
    ({-1: 3}, "'join_at': got -1; allowed: an agent id 0..3"),
    ({1: 0}, "'join_at': got 0; allowed: an integer >= 1"),
    ({1: 5000}, "'join_at': agent 1 joins at round 5000, past the round bound 80; allowed: 1..80"),
    ({0: 2, 1: 2, 2: 2, 3: 2}, "one agent present from the start"),
    ([[1, 2], [1, 3]], "each agent at most once"),
    ("later", "allowed: a mapping {agent: round}"),
])
def test_bad_joins_are_one_line_errors_naming_the_field(join_at, words):
    with pytest.raises(ConfigError, match=re.escape(words)) as info:
        TaskAllocEnv("train_small", join_at=join_at)
    assert "\n" not in str(info.value)


def test_a_scheduled_failure_before_the_join_is_refused():
    with pytest.raises(ConfigError, match=r"'dropout_schedule'.*a failure after agent 1 joins \(join_at round 5\)"):
        TaskAllocEnv("train_small", join_at={1: 5}, dropout_schedule=[[1, 4]])


def test_join_at_reads_a_mapping_or_pairs_and_round_trips():
    cfg = TaskAllocConfig().replace(join_at={3: 5, 1: 2})
    assert cfg.join_at == ((1, 2), (3, 5)) == TaskAllocConfig().replace(join_at=[[3, 5], [1, 2]]).join_at
    assert cfg.replace() == cfg and hash(cfg)
