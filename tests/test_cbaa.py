"""CBAA (Choi et al. 2009; thesis §2.2.3, Alg 1–2): a hand-computed 3 × 3 example round by round, CBAA = CBBA with
bundles of one, conflict-free convergence over random single-agent scenarios, at least half the optimum of the
single-assignment problem, and the runners (registry, compare, the direct solver, the benchmark)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from helpers import agent, build, check_converged_allocation, check_tables, examples, run_episode, task
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_properties import make_env, scenario_config

from taskalloc.cli import main
from taskalloc.evaluation.episodes import skip_reason
from taskalloc.policies import CBAAPolicy, exact, make_policy, rollout
from taskalloc.policies.fast import solve
from taskalloc_env import TaskAllocEnv
from taskalloc_env.actions import PASS, encode_bid

# c_ij = c̄_j − 10 · |x_i − x_j| (every window opens late, at 100, 110 and 120 min, so each agent waits and earns c̄_j;
# γ = 10 per km):
#              T0 (x=1, 100)  T1 (x=−1.2, 100)  T2 (x=9, 60)
#   a0 (x=0)        90            88               −30
#   a1 (x=2.5)      85            63               −5
#   a2 (x=10)       10           −12                50
GAINS = np.array([[90.0, 88.0, -30.0], [85.0, 63.0, -5.0], [10.0, -12.0, 50.0]])


def three_by_three() -> TaskAllocEnv:
    s = build([agent(0.0), agent(2.5), agent(10.0)],
              [task(1.0), task(-1.2, start=110.0), task(9.0, reward=60.0, start=120.0)], arena=(20.0, 10.0, 10.0))
    return TaskAllocEnv(s, dtype="float64", invalid_action="raise")


def test_the_worked_example_round_by_round():
    """Round 0 (Alg 1): every agent is unassigned and takes its best task, a0 and a1 both T0 (90, 85), a2 T2 (50);
    then each holds one and passes, although a0 and a1 could still bid T1 (78 after T0: CBBA would). Consensus
    (Alg 2): a0's 90 beats a1's 85 on T0, a1 loses it. Round 1: only a1 is unassigned; T0 is no longer valid for it
    (85 > 90 fails, eq. (2.2)), so it takes T1 (63). The result, 203, is the sequential greedy's and not the
    optimum: a0 → T1, a1 → T0, a2 → T2 makes 88 + 85 + 50 = 223, and 203 ≥ ½ · 223. CBBA, free to chain, gives
    a0 both T0 and T1 (90 + 78) and scores 218 (thesis §2.2.4: CBAA "does not take into account future
    selections")."""
    env = three_by_three()
    observations, infos = env.reset(seed=0)
    protocol = env.protocol
    positive = np.where(GAINS > 0, GAINS, 0.0)
    np.testing.assert_allclose(protocol.view().gain, positive)
    policy = make_policy("cbaa")
    policy.start(env, 0)
    actions = policy.act(observations, infos)
    assert actions == {"uav_0": encode_bid(0), "uav_1": encode_bid(0), "uav_2": encode_bid(2)}
    observations, *_, infos = env.step(actions)
    np.testing.assert_array_equal(protocol.view().can_bid, [[False, True, False], [False, True, False],
                                                            [False, False, False]])
    assert policy.act(observations, infos) == dict.fromkeys(env.agents, PASS), "one task each: everyone passes"
    observations, *_, infos = env.step(dict.fromkeys(env.agents, PASS))
    assert protocol.round == 1 and protocol.knowledge.bundles == [[0], [], [2]]
    assert protocol.knowledge.winner[1, 0] == 0 and protocol.knowledge.winning_bid()[1, 0] == 90.0
    assert not protocol.view().can_bid[1, 0], "T0: 85 does not beat 90 (h_ij, eq. (2.2))"
    assert policy.act(observations, infos)["uav_1"] == encode_bid(1)
    allocation = rollout(env, policy, seed=0)
    assert allocation.paths == ((0,), (1,), (2,)) and allocation.score == pytest.approx(203.0)
    assert allocation.converged and not allocation.conflicts
    # the optimum of the single-assignment problem, by enumeration of the 3! matchings, and by the exact solver
    best = max(sum(max(GAINS[i, j], 0.0) for i, j in enumerate(perm)) for perm in itertools.permutations(range(3)))
    assert best == 223.0
    optimum = exact(env.scenario, env.config.replace(max_bundle=1))
    assert optimum.score == pytest.approx(best) and optimum.paths == ((1,), (0,), (2,))
    assert allocation.score >= 0.5 * optimum.score
    cbba = rollout(env, make_policy("cbba"), seed=0)
    assert cbba.paths == ((0, 1), (), (2,)) and cbba.score == pytest.approx(218.0)


@st.composite
def single_agent_config(draw, limited_comms: bool = False):
    """``test_properties``' scenarios with every L_j = 1 (no task mix: equipment types are dropped)."""
    kw = draw(scenario_config(limited_comms=limited_comms))
    kw.pop("task_mix", None)
    kw.pop("agent_types", None)
    kw["agents_per_task"] = 1
    return kw


@settings(max_examples=examples(200), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kw=single_agent_config(), seed=st.integers(0, 2**16))
def test_cbaa_converges_conflict_free_with_one_task_per_agent(kw, seed):
    """Thesis §2.2.3: CBAA converges to a conflict-free assignment; every agent holds at most one task; the table
    invariants hold after every step and the final allocation passes every check of ``test_properties``."""
    policy = CBAAPolicy()
    env = make_env(kw, policy)
    episode = run_episode(env, policy, seed, check=check_tables)
    check_converged_allocation(env, episode)
    assert all(len(path) <= 1 for path in episode.allocation.paths)


@settings(max_examples=examples(100), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kw=single_agent_config(), seed=st.integers(0, 2**16))
def test_cbaa_is_cbba_with_bundles_of_one(kw, seed):
    """Thesis §2.2.4: "When the number of assignments an agent is allowed is limited to 1, the CBBA will produce the
    same result as the CBAA": CBAA here and CBBA under ``max_bundle = 1`` reach the same allocation in the same
    rounds with the same messages."""
    cbaa = rollout(TaskAllocEnv(**kw), CBAAPolicy(), seed=seed)
    cbba = rollout(TaskAllocEnv(**{**kw, "max_bundle": 1}), make_policy("cbba"), seed=seed)
    assert cbaa.paths == cbba.paths and cbaa.score == cbba.score
    assert (cbaa.counters.rounds, cbaa.counters.messages, cbaa.counters.bids) == \
        (cbba.counters.rounds, cbba.counters.messages, cbba.counters.bids)


@settings(max_examples=examples(200), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kw=single_agent_config(), seed=st.integers(0, 2**16))
def test_cbaa_scores_at_least_half_the_single_assignment_optimum(kw, seed):
    """Choi et al. 2009 (thesis §2.2.3): CBAA's assignment is the sequential greedy's, at least 50 % of the optimum
    of the single-assignment problem. Without prerequisites the score of a single assignment is the sum of its
    c_ij, a matching's weight, and greedy matching is a ½-approximation; the optimum is ``exact`` under
    ``max_bundle = 1`` (at most 6 agents × 8 tasks here)."""
    kw.pop("prerequisites", None)
    kw.pop("prereq_mode", None)
    kw.pop("prereq_timing", None)
    env = TaskAllocEnv(**kw)
    allocation = rollout(env, CBAAPolicy(), seed=seed)
    optimum = exact(env.scenario, env.config.replace(max_bundle=1))
    assert allocation.converged and not allocation.conflicts
    assert allocation.score >= 0.5 * optimum.score - 1e-9, (allocation.score, optimum.score)


def test_cbaa_refuses_multi_agent_tasks_and_is_skipped_where_they_exist():
    env = TaskAllocEnv("train_small")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="CBAA assigns single-agent tasks only"):
        make_policy("cbaa").start(env, 0)
    assert skip_reason("cbaa", env.config) == "CBAA assigns single-agent tasks only (every L_j = 1)"
    assert skip_reason("cbaa", env.config.replace(agents_per_task=1)) is None


@pytest.mark.parametrize("seed", range(3))
def test_the_direct_solver_reproduces_cbaa_episodes(seed):
    env = TaskAllocEnv("train_small", agents_per_task=1)
    episode = rollout(env, make_policy("cbaa"), seed=seed)
    assert solve(env.scenario, env.config, "cbaa") == episode


def test_compare_has_a_cbaa_row_where_every_task_needs_one_agent(capsys):
    assert main(["compare", "--episodes", "2", "--set", "agents_per_task=1", "--set", "n_agents=4", "--set",
                 "n_tasks=8", "--no-learned", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "| CBAA |" in out and "| CBBA |" in out


def test_the_benchmark_runs_cbaa_on_the_single_agent_task(tmp_path, capsys):
    """Async is the suite's task with every L_j = 1: CBAA runs there (with its asynchronous consensus); the
    multi-agent tasks are not applicable."""
    out = tmp_path / "cbaa"
    assert main(["benchmark", "--policy", "cbaa", "--tasks", "taskalloc/Async-v0", "taskalloc/Small-v0",
                 "--episodes", "2", "--out", str(out)]) == 0
    text = (out / "summary.md").read_text()
    assert "| taskalloc/Async-v0 | 2 |" in text
    assert "| taskalloc/Small-v0 | 0 | not applicable: CBAA assigns single-agent tasks only" in text
