"""PI (Zhao, Meng & Chung 2016) as this environment can express it (``policies/pi.py``): inclusion by the largest
improvement over the holder, removal of overstated tasks by release actions (each pair once), conflict-free
convergence over random single-agent scenarios, and the runners."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest
from helpers import (
    agent,
    build,
    check_converged_allocation,
    check_tables,
    examples,
    replay,
    run_episode,
    scoring_options,
    task,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_cbaa import single_agent_config
from test_properties import make_env

from taskalloc.cli import main
from taskalloc.policies import PIPolicy, make_policy, rollout
from taskalloc_env import TaskAllocEnv
from taskalloc_env.actions import PASS, ActionKind, decode, encode_bid


def test_inclusion_takes_the_largest_improvement_over_the_holder_not_the_largest_gain():
    """a0 holds T0 at 90 after round 0. In round 1, a1 may outbid it (c = 95 > 90) or take the free T1 (c = 60): CBBA
    takes the larger gain, T0; PI the larger improvement of the team, T1 (60 − 0 > 95 − 90)."""
    s = build([agent(1.0), agent(0.5)], [task(0.0), task(0.5, reward=60.0, start=150.0)], arena=(10.0, 10.0, 10.0))
    env = TaskAllocEnv(s, dtype="float64", invalid_action="raise", release_actions=True)
    env.reset(seed=0)
    env.step({"uav_0": encode_bid(0), "uav_1": PASS})
    observations, *_, infos = env.step({"uav_0": PASS, "uav_1": PASS})
    view = env.protocol.view()
    assert view.can_bid[1].tolist() == [True, True] and view.gain[1].tolist() == [95.0, 60.0]
    pi, cbba = PIPolicy(), make_policy("cbba")
    for policy in (pi, cbba):
        policy.start(env, 0)
    assert pi.act(observations, infos)["uav_1"] == encode_bid(1)
    assert cbba.act(observations, infos)["uav_1"] == encode_bid(0)


def test_removal_releases_the_largest_overstatement_once_with_rho_from_the_path():
    """Along whole episodes: every release PI makes is of the task whose shared bid most exceeds its significance
    ρ_ij = S_i(p_i) − S_i(p_i ⊖ j) (computed here by the reference replay of (3.7)–(3.10)), and no (agent, task) pair
    is released twice."""
    released: Counter = Counter()
    checked = 0
    for seed in range(6):
        policy = PIPolicy()
        env = TaskAllocEnv("train_small", agents_per_task=1, dtype="float64", **policy.env_overrides)
        observations, infos = env.reset(seed=seed)
        policy.start(env, seed)
        m = env.config.n_tasks
        while env.agents:
            kn = env.protocol.knowledge
            actions = policy.act(observations, infos)
            for name, action in actions.items():
                kind, j = decode(action, m)
                if kind is not ActionKind.RELEASE:
                    continue
                i = env.agent_index[name]
                path = kn.paths[i]
                score = replay(env.scenario, i, path, **scoring_options(env)).score
                excess = {k: float(kn.groups.own[i, k]) - (score - replay(env.scenario, i, [x for x in path if x != k],
                                                                          **scoring_options(env)).score)
                          for k in path if released[seed, i, k] == 0}
                assert excess[j] > 0 and excess[j] == pytest.approx(max(excess.values()), abs=1e-9)
                released[seed, i, j] += 1
                checked += 1
            observations, *_, infos = env.step(actions)
        assert env.evaluate().counters.releases == sum(v for (s, *_), v in released.items() if s == seed)
    assert checked > 0 and max(released.values()) == 1


@settings(max_examples=examples(200), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kw=single_agent_config(), seed=st.integers(0, 2**16))
def test_pi_converges_conflict_free_over_random_single_agent_scenarios(kw, seed):
    """Every invariant of ``test_properties`` after every step and at the end (agreement, no conflicts, windows,
    prerequisites, return = score), with at most one release per (agent, task)."""
    policy = PIPolicy()
    env = make_env(kw, policy)
    episode = run_episode(env, policy, seed, check=check_tables)
    check_converged_allocation(env, episode)
    assert episode.allocation.counters.releases <= env.config.n_agents * env.config.n_tasks


@pytest.mark.parametrize("seed", range(3))
def test_pi_converges_under_acbba(seed):
    policy = PIPolicy()
    env = TaskAllocEnv("train_small", agents_per_task=1, consensus="acbba", **policy.env_overrides)
    allocation = rollout(env, policy, seed=seed)
    assert allocation.converged and allocation.agreement and not allocation.conflicts


def test_pi_needs_release_actions_and_single_agent_tasks():
    env = TaskAllocEnv("train_small", agents_per_task=1)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"needs an environment with \{'release_actions': True\}"):
        PIPolicy().start(env, 0)
    env = TaskAllocEnv("train_small", release_actions=True)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="PI assigns single-agent tasks only"):
        PIPolicy().start(env, 0)


def test_compare_has_a_pi_row_where_every_task_needs_one_agent(capsys):
    assert main(["compare", "--episodes", "2", "--set", "agents_per_task=1", "--set", "n_agents=4", "--set",
                 "n_tasks=8", "--no-learned", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "| PI |" in out
    assert np.isfinite(float(out.split("| PI |")[1].split("±")[0]))
