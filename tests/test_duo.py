"""Preferred-duo CBBA (policies/duo.py): the split, the exclusion of thesis eq. (4.1), the reward, convergence."""

from __future__ import annotations

import numpy as np
import pytest

from taskalloc.evaluation.episodes import Episode, run_episode, skip_reason
from taskalloc.policies import CBBAPolicy, rollout
from taskalloc.policies.duo import DuoCBBAPolicy, both_parts, duo_env, duo_partners, preferred_duo_cbba, split_duo
from taskalloc_env import Agent, Scenario, Task, TaskAllocEnv, resolve_config
from taskalloc_env.allocation import Allocation
from taskalloc_env.scoring import ScoringModel

CFG = resolve_config("default", agents_per_task=1)
GAMMA = 0.8


def one_task(*agent_x: float) -> Scenario:
    """Agents on the x axis, one task at the origin starting at 10 (everyone arrives early: full reward)."""
    agents = [Agent(position=(x, 0.0, 0.0), speed=1.0) for x in agent_x]
    task = Task(position=(0.0, 0.0, 0.0), reward=100.0, start=10.0, end=20.0, duration=5.0)
    return Scenario.from_entities(agents, [task], arena=(5.0, 5.0, 2.0))


def test_split_makes_a_lead_and_a_helper_part_of_every_task():
    env = TaskAllocEnv(CFG)
    env.reset(seed=4)
    base = env.scenario
    duo = split_duo(base)
    m = base.n_tasks
    assert duo.n_tasks == 2 * m and (duo.task_agents == 1).all()
    np.testing.assert_array_equal(duo.task_reward, np.r_[base.task_reward, 0.5 * base.task_reward])  # 100 + 50
    for name in ("task_pos", "task_start", "task_end", "task_duration"):
        np.testing.assert_array_equal(getattr(duo, name)[:m], getattr(duo, name)[m:])
    assert duo.task_prereqs[m:, :m].diagonal().all() and duo.task_prereqs.sum() == m     # helper j+M needs lead j
    np.testing.assert_array_equal(duo_partners(duo), np.r_[np.arange(m, 2 * m), np.arange(m)])
    with pytest.raises(ValueError, match="not a preferred-duo scenario"):
        duo_partners(base)
    env2 = TaskAllocEnv(CFG.replace(agents_per_task=2))
    env2.reset(seed=0)
    with pytest.raises(ValueError, match="single-agent"):
        split_duo(env2.scenario)


def test_an_agent_never_holds_both_parts():
    """One agent, one task: plain CBBA on the split scenario takes the helper part after the lead (it is biddable
    once the lead holds a bid); with (4.1) the agent stops at the lead."""
    plain = rollout(duo_env(one_task(1.0), CFG), CBBAPolicy(), seed=0)
    assert both_parts(plain, 1) == [(0, 0)]
    duo = rollout(duo_env(one_task(1.0), CFG), DuoCBBAPolicy(), seed=0)
    assert duo.paths == ((0,),) and both_parts(duo, 1) == []
    assert duo.score == pytest.approx(100 - GAMMA * 1.0)


def test_two_agents_share_a_task_for_150():
    """The closer agent takes the lead (bid 100 − 0.8·1 > 100 − 0.8·2), the other the helper: 100 + 50 in total,
    each paying its own travel; both parts valid."""
    alloc = preferred_duo_cbba(one_task(1.0, 2.0), CFG)
    assert alloc.paths == ((0,), (1,)) and alloc.valid_tasks == (0, 1)
    assert alloc.score == pytest.approx(150 - GAMMA * (1.0 + 2.0))
    assert alloc.converged and not alloc.conflicts


def test_the_helper_part_pays_only_with_the_lead_done():
    duo = split_duo(one_task(1.0, 2.0))
    model = ScoringModel.from_config(duo, CFG.replace(prereq_timing="none"))
    alone = Allocation.from_paths(model, [[], [1]])               # helper without a lead: travel only
    assert alone.valid_tasks == () and alone.score == pytest.approx(-GAMMA * 2.0)
    both = Allocation.from_paths(model, [[0], [1]])
    assert both.valid_tasks == (0, 1)


def test_helper_is_not_biddable_before_anyone_holds_the_lead():
    env = duo_env(one_task(1.0, 2.0), CFG)
    obs, _ = env.reset(seed=0)
    mask = obs["uav_0"]["action_mask"]
    assert mask[1] == 1 and mask[2] == 0                             # lead biddable, helper not yet


@pytest.mark.parametrize("n_agents, n_tasks", [(2, 6), (4, 10), (7, 12)])
def test_preferred_duo_converges_without_conflicts_or_double_parts(n_agents, n_tasks):
    cfg = resolve_config("default", n_agents=n_agents, n_tasks=n_tasks, agents_per_task=1)
    env = TaskAllocEnv(cfg)
    for seed in range(8):
        env.reset(seed=seed)
        alloc = preferred_duo_cbba(env.scenario, cfg)        # raises if an agent holds both parts
        assert alloc.converged and alloc.agreement and not alloc.conflicts
        assert set(alloc.valid_tasks) <= set(range(2 * n_tasks))
        helpers = [j for j in alloc.valid_tasks if j >= n_tasks]
        assert all(j - n_tasks in alloc.valid_tasks for j in helpers)     # a paid helper has its lead done


def test_the_runner_pairs_duo_with_cbba_and_counts_messages():
    cfg = resolve_config("default", n_agents=4, n_tasks=8, agents_per_task=1)
    duo, cbba = (run_episode(Episode(s, cfg, 3)) for s in ("cbba-duo", "cbba"))
    assert duo["solver"] == "CBBA preferred duo" and duo["instance"] == cbba["instance"]
    assert duo["messages"] > 0 and duo["comm_steps_to_agreement"] <= duo["comm_steps"]
    assert skip_reason("cbba-duo", cfg.replace(agents_per_task=2)) is not None
