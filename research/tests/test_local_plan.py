"""The local plan (``research.policies.local_plan``): a round 0 from one agent's own knowledge, and its command
line."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from research.evaluation import local_plan
from research.policies.handover import Handover
from research.policies.local_plan import SOLVERS, LocalPlanPolicy
from taskalloc.policies import make_policy, rollout
from taskalloc.policies.centralised import exact
from taskalloc_env import TaskAllocEnv
from taskalloc_env.errors import run_cli


def bound(env: TaskAllocEnv, seed: int, samples: int = 4, solver: str = "exact") -> LocalPlanPolicy:
    env.reset(seed=seed)
    policy = LocalPlanPolicy(samples, solver)
    policy.start(env, seed)
    return policy


@pytest.mark.slow
def test_the_plan_does_not_depend_on_where_the_teammates_are():
    """Each agent's shares are the same when its teammates start elsewhere, although the optimum moves with them."""
    env = TaskAllocEnv("train_small")
    optimum_moved = False
    for seed in (10_000, 10_001):
        policy = bound(env, seed, samples=2)
        scenario = env.scenario
        for agent in range(scenario.n_agents):
            moved = scenario.agent_pos.copy()
            others = np.arange(scenario.n_agents) != agent
            moved[others, :2] = np.asarray(scenario.arena[:2]) - moved[others, :2]    # teammates mirrored
            elsewhere = dataclasses.replace(scenario, agent_pos=moved)
            np.testing.assert_array_equal(policy.shares(scenario, agent, np.random.default_rng([seed, agent])),
                                          policy.shares(elsewhere, agent, np.random.default_rng([seed, agent])))
            optimum_moved |= exact(scenario, env.config).paths[agent] != exact(elsewhere, env.config).paths[agent]
        # the plans it plays are the ones drawn from each agent's own start with the episode's seed
        assert policy.plans == tuple(policy.plan(scenario, i, np.random.default_rng([seed, i]))
                                     for i in range(scenario.n_agents))
    assert optimum_moved


@pytest.mark.parametrize("solver", sorted(SOLVERS))
def test_alone_it_plans_its_solvers_path_and_reaches_its_score(solver):
    """With one agent every drawn team is the instance itself: the plan is the solver's path, played in round 0."""
    env = TaskAllocEnv("train_small", n_agents=1, agents_per_task=1)
    for seed in (3, 4, 5):
        policy = bound(env, seed, 3, solver)
        best = SOLVERS[solver](env.scenario, env.config)
        assert set(policy.plans[0]) == set(best.paths[0]) and best.paths[0]
        assert rollout(env, policy, seed=seed).score == pytest.approx(best.score, rel=1e-9)


@pytest.mark.slow
def test_it_bids_only_in_round_0_and_then_passes():
    env = TaskAllocEnv("train_small")
    policy = LocalPlanPolicy(4)
    observations, infos = env.reset(seed=10_003)
    policy.start(env, 10_003)
    acted = {0: [], 1: []}
    while env.agents:
        actions = policy.act({a: observations[a] for a in env.agents})
        for agent, action in actions.items():
            acted[min(infos[agent]["round"], 1)].append(action)
        observations, _, _, _, infos = env.step(actions)
    assert any(acted[0]) and not any(acted[1])


@pytest.mark.slow
def test_its_plans_are_reused_for_the_same_instance_and_drawn_again_for_another():
    env = TaskAllocEnv("train_small")
    policy = bound(env, 10_000)
    first = policy.plans
    env.reset(seed=10_001)
    policy.start(env, 10_001)
    env.reset(seed=10_000)
    policy.start(env, 10_000)
    assert policy.plans is first and len(policy._memo) == 2


@pytest.mark.parametrize("samples", [0, -1, 1.5, True])
def test_a_bad_number_of_draws_or_an_unknown_solver_is_refused_by_name(samples):
    with pytest.raises(ValueError, match="samples must be an integer >= 1"):
        LocalPlanPolicy(samples)
    with pytest.raises(ValueError, match="unknown solver 'sgama'; known: exact, lns"):
        LocalPlanPolicy(2, "sgama")


def test_the_command_line_plays_each_policy_alone_and_after_the_local_plan(capsys):
    table = local_plan.main(["--policy", "cbgabi", "--samples", "2", "--episodes", "2"])
    labels = [line.split(" | ")[0].lstrip("| ") for line in table.splitlines()[2:]]
    assert labels == ["exact optimum", "cbgabi", "local plan (2 draws) for round 0, then cbgabi"]
    assert "train_small, seeds 10000–10001" in capsys.readouterr().out


@pytest.mark.slow
def test_with_the_lns_reference_the_command_line_plays_at_the_default_size():
    table = local_plan.main(["--scenario", "default", "--reference", "lns", "--policy", "cbgabi", "--samples", "1",
                             "--episodes", "1"])
    labels = [line.split(" | ")[0].lstrip("| ") for line in table.splitlines()[2:]]
    assert "% of LNS" in table.splitlines()[0]
    assert labels == ["LNS", "cbgabi", "local plan (1 draws, lns) for round 0, then cbgabi"]


@pytest.mark.slow
def test_the_local_plan_then_cbgabi_plays_valid_actions_on_many_instances():
    policy = Handover(LocalPlanPolicy(2), make_policy("cbgabi"), 1)
    env = TaskAllocEnv("train_small", **policy.env_overrides)
    for seed in range(6):
        allocation = rollout(env, policy, seed=seed)       # an action outside the mask would raise
        assert not allocation.conflicts


@pytest.mark.parametrize("argv, words", [
    (["--samples", "0"], ("--samples", ">= 1")),
    (["--episodes", "0"], ("--episodes", ">= 1")),
    (["--policy", "nonsense"], ("--policy nonsense", "unknown policy")),
    (["--scenario", "default"], ("--scenario default", "exact", "--reference lns")),
])
def test_bad_arguments_are_one_line_and_exit_2(argv, words, capsys):
    assert run_cli(lambda: local_plan.main(argv)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ")
    assert all(w in err[0] for w in words), err[0]
