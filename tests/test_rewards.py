"""The reward's scale, the episode record of the final infos and the default step limit (``taskalloc_env.rewards``,
``TaskAllocEnv``): the return of a whole episode is the score over the documented scale, the record holds the
episode's figures on the step an agent's episode ends and never before, and the default ``max_cycles`` cuts a
runaway episode but no measured one."""

from __future__ import annotations

import math

import numpy as np
import pytest

from taskalloc.policies import make_policy
from taskalloc_env import TaskAllocEnv
from taskalloc_env.env import STEPS_PER_BOUND_ROUND
from taskalloc_env.errors import ConfigError
from taskalloc_env.rewards import EPISODE_FIGURES

SMALL = {"n_agents": 4, "n_tasks": 6, "agents_per_task": [1, 2], "start_time_range": [0.0, 30.0]}


def play(env: TaskAllocEnv, policy_name: str, seed: int) -> list[tuple]:
    """One episode of ``policy_name``: per step (rewards, terminations, truncations, infos)."""
    policy = make_policy(policy_name)
    observations, infos = env.reset(seed=seed)
    policy.start(env, seed)
    steps = []
    while env.agents:
        observations, rewards, terminations, truncations, infos = env.step(policy.act(observations, infos))
        steps.append((rewards, terminations, truncations, infos))
    return steps


def team_return(steps: list[tuple], agent: str = "uav_0") -> float:
    return sum(rewards[agent] for rewards, *_ in steps if agent in rewards)


def total_task_reward(env: TaskAllocEnv) -> float:
    """Σ_j L_j · c̄_j (per_agent split) or Σ_j c̄_j (total split), from the instance's arrays."""
    s = env.scenario
    if env.config.reward_split == "total":
        return float(s.task_reward.sum())
    return float((s.task_reward * s.task_agents).sum())


# -- the scale ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("split", ["per_agent", "total"])
@pytest.mark.parametrize("policy", ["random", "cbgabi"])
def test_the_default_return_is_the_score_over_the_total_task_reward(split, policy):
    env = TaskAllocEnv(**SMALL, reward_split=split, **make_policy(policy).env_overrides)
    for seed in range(3):
        steps = play(env, policy, seed)
        score = env.evaluate().score
        assert env.reward_scale == pytest.approx(total_task_reward(env), rel=1e-12)
        assert team_return(steps) == pytest.approx(score / total_task_reward(env), abs=1e-9)
        assert team_return(steps) <= 1.0


def test_raw_gives_the_score_and_a_number_divides_by_it():
    for scale, divisor in (("raw", 1.0), (100.0, 100.0), (7, 7.0)):
        env = TaskAllocEnv(**SMALL, reward_scale=scale)
        steps = play(env, "random", seed=4)
        assert env.reward_scale == divisor
        assert team_return(steps) == pytest.approx(env.evaluate().score / divisor, abs=1e-9)


def test_the_scale_follows_the_instance_and_is_known_from_reset():
    env = TaskAllocEnv(**SMALL)
    with pytest.raises(RuntimeError, match="reset"):
        _ = env.reward_scale
    scales = set()
    for seed in range(6):
        env.reset(seed=seed)
        scales.add(env.reward_scale)
        assert env.reward_scale == total_task_reward(env)
    assert len(scales) > 1                               # L_j is drawn from {1, 2}: the total changes


def test_an_instance_that_pays_nothing_is_scaled_by_one():
    from helpers import agent, build, task

    scenario = build([agent(0, 0), agent(1, 1)], [task(0.5, 0.5, reward=0.0)])
    env = TaskAllocEnv(scenario)
    steps = play(env, "cbga", seed=0)
    assert env.reward_scale == 1.0
    assert team_return(steps) == pytest.approx(env.evaluate().score, abs=1e-9)


@pytest.mark.parametrize("value", ["2", "Raw", "", 0, 0.0, -1.0, math.inf, math.nan, True, None, [1.0]])
def test_a_bad_reward_scale_is_one_line_naming_the_allowed_values(value):
    with pytest.raises(ConfigError) as info:
        TaskAllocEnv(**SMALL, reward_scale=value)
    text = str(info.value)
    assert "\n" not in text and "reward_scale" in text and "'total_reward', 'raw'" in text and repr(value) in text


def test_the_scale_changes_no_observation():
    traces = []
    for scale in ("total_reward", "raw", 3.0):
        env = TaskAllocEnv(**SMALL, reward_scale=scale, task_quitting=True)
        observations, infos = env.reset(seed=2)
        trace = [observations]
        policy = make_policy("cbgabi")
        policy.start(env, 2)
        while env.agents:
            observations, *_, infos = env.step(policy.act(observations, infos))
            trace.append(observations)
        traces.append(trace)
    for other in traces[1:]:
        assert len(other) == len(traces[0])
        for a, b in zip(traces[0], other):
            assert all(np.array_equal(a[k]["observation"], b[k]["observation"]) for k in a)


# -- the episode record ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("scale", ["total_reward", "raw"])
def test_the_episode_record_is_in_the_final_infos_only_and_holds_the_figures(scale):
    env = TaskAllocEnv(**SMALL, reward_scale=scale, task_quitting=True)
    for seed in range(3):
        steps = play(env, "random", seed)
        for *_, infos in steps[:-1]:
            assert not any("episode" in info for info in infos.values())
        allocation = env.evaluate()
        final = steps[-1][3]
        assert set(final) == set(env.possible_agents)
        for agent, info in final.items():
            record = info["episode"]
            assert set(record) == {"r", "l", *EPISODE_FIGURES}
            assert record["r"] == pytest.approx(team_return(steps, agent), abs=1e-12)
            assert record["r"] == pytest.approx(allocation.score / env.reward_scale, abs=1e-9)
            assert record["l"] == len(steps)
            assert record["score"] == allocation.score
            assert record["valid_tasks"] == len(allocation.valid_tasks)
            assert record["conflicts"] == len(allocation.conflicts)
            assert record["rounds"] == allocation.counters.rounds
            assert record["messages"] == allocation.counters.messages
            assert record["converged"] == allocation.converged
        assert len({id(info["episode"]) for info in final.values()}) == len(final)   # a dict of its own each


def test_a_failed_agent_gets_its_record_when_it_leaves():
    env = TaskAllocEnv(n_agents=5, n_tasks=6, agents_per_task=[1, 2], dropouts=2, dropout_rounds=[1, 2])
    for seed in range(4):
        steps = play(env, "cbga", seed)
        for agent in env.possible_agents:
            ended = [k for k, (_, terminations, truncations, _) in enumerate(steps)
                     if terminations.get(agent) or truncations.get(agent)]
            assert ended, agent
            last = ended[0]
            for k, (_, _, _, infos) in enumerate(steps):
                assert ("episode" in infos.get(agent, {})) == (k == last), (agent, k, last)
            record = steps[last][3][agent]["episode"]
            assert record["l"] == last + 1
            assert record["r"] == pytest.approx(team_return(steps[: last + 1], agent), abs=1e-12)
        assert any(ends < len(steps) - 1 for ends in
                   [next(k for k, (_, t, _, _) in enumerate(steps) if t.get(a)) for a in env.possible_agents])


def test_episode_stats_false_leaves_the_record_out():
    env = TaskAllocEnv(**SMALL, episode_stats=False)
    steps = play(env, "cbga", seed=0)
    assert not any("episode" in info for *_, infos in steps for info in infos.values())
    with pytest.raises(ConfigError, match="episode_stats must be True or False, got 1"):
        TaskAllocEnv(**SMALL, episode_stats=1)


# -- the default step limit --------------------------------------------------------------------------------------
class Eager:
    """Never passes while its mask allows anything else: the last allowed action (a quit before a bid)."""

    def act(self, observations, infos):
        return {a: int(np.flatnonzero(o["action_mask"])[-1]) for a, o in observations.items()}


def eager_episode(env: TaskAllocEnv, seed: int) -> tuple[int, bool, bool]:
    """Steps, terminated, truncated of an episode of ``Eager``."""
    observations, infos = env.reset(seed=seed)
    steps, policy = 0, Eager()
    while env.agents:
        observations, _, terminations, truncations, infos = env.step(policy.act(observations, infos))
        steps += 1
    return steps, all(terminations.values()), all(truncations.values())


@pytest.mark.parametrize(("consensus", "per_round"), [("sync", STEPS_PER_BOUND_ROUND), ("every_step", 1),
                                                      ("acbba", 1)])
def test_the_default_step_limit_is_a_multiple_of_the_round_bound(consensus, per_round):
    env = TaskAllocEnv(**SMALL, consensus=consensus)
    assert env.max_cycles == per_round * env.round_bound
    assert TaskAllocEnv(**SMALL, consensus=consensus, max_cycles=7).max_cycles == 7
    if consensus == "sync":
        assert env.max_cycles < env.step_bound


def test_a_policy_that_never_passes_while_it_can_bid_still_finishes():
    """On the default scenario with quitting, ``Eager`` converges long before the default limit (2000 steps)."""
    env = TaskAllocEnv(task_quitting=True, delta=0, quit_block="none")
    for seed in range(3):
        steps, terminated, truncated = eager_episode(env, seed)
        assert terminated and not truncated and steps < env.max_cycles / 10


def test_the_default_limit_cuts_an_episode_at_five_steps_per_bound_round():
    """With a round bound of 2 the default limit is 10 steps; ``Eager``'s first round alone takes longer."""
    env = TaskAllocEnv(max_rounds=2)
    assert env.max_cycles == 2 * STEPS_PER_BOUND_ROUND
    steps, terminated, truncated = eager_episode(env, seed=0)
    assert (steps, terminated, truncated) == (env.max_cycles, False, True)
    assert env.protocol.round < 2                        # the step limit cut it, not the round bound


@pytest.mark.slow
def test_the_default_limit_never_cuts_a_baseline_or_a_committed_policy_on_any_suite_task():
    """Every test seed of every suite task: random, CBGA, CBGABI, ACBBA (where L_j = 1) and the committed learned
    policies (where they fit) finish with at least twice their longest episode to spare
    (``python -m evaluation.episode_stats`` prints the table of docs/decisions.md)."""
    from taskalloc.evaluation.episode_stats import POLICIES, measure
    from taskalloc_env.suite import TASKS

    summary = measure(list(TASKS), POLICIES, episodes=None, jobs=2)
    assert {r["policy"] for r in summary} >= {"random", "cbga", "cbgabi", "acbba"}
    short = [(r["task"], r["policy"], r["max_steps"], r["max_cycles"]) for r in summary if r["margin"] < 2]
    assert not short, short
