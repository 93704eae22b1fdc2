"""The collaborative-visit generator (``scenario.visit``, ``configs/scenarios/visit.yaml``), the generators' config
checks (``generators.CHECKS``) and Manhattan travel (``travel_metric``)."""

from __future__ import annotations

import numpy as np
import pettingzoo
import pytest
from helpers import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from taskalloc.policies import make_policy, rollout
from taskalloc_env import ConfigError, Scenario, TaskAllocEnv, generate, resolve_config
from taskalloc_env.generators import CHECKS, GENERATORS, register_generator
from taskalloc_env.observation import RELATIVE_BOUND
from taskalloc_env.scenario import Agent, Task, visit_starts
from taskalloc_env.scoring import ScoringModel

RNG = np.random.default_rng


def draw(seed: int = 0, **overrides) -> Scenario:
    return generate(resolve_config("visit", **overrides), RNG(seed))


# -- the scenario of the study: the DCTA benchmark's layout ------------------------------------------------------
def test_visit_yaml_is_four_agents_on_the_left_edge_and_ten_single_agent_targets_on_free_cells():
    """4 agents at (0, 0), (0, 6), (0, 12), (0, 18) of the 19 × 19 grid; 10 targets with L_j = 1 on distinct integer
    cells of the floor, none on a start, open from 0 with no deadline."""
    for seed in range(20):
        s = draw(seed)
        assert s.agent_pos.tolist() == [[0, 0, 0], [0, 6, 0], [0, 12, 0], [0, 18, 0]]
        assert s.n_tasks == 10 and (s.task_agents == 1).all()
        xy = s.task_pos[:, :2]
        assert (xy == np.round(xy)).all() and (xy >= 0).all() and (xy <= 18).all() and (s.task_pos[:, 2] == 0).all()
        assert len({tuple(p) for p in xy.tolist()}) == 10
        assert not ({tuple(p) for p in xy.tolist()} & {tuple(p) for p in s.agent_pos[:, :2].tolist()})
        assert (s.task_start == 0).all() and np.isinf(s.task_end).all() and (s.task_duration == 0).all()
        assert not s.has_equipment and not s.has_prerequisites


@settings(max_examples=examples(200), deadline=None)
@given(n_agents=st.integers(1, 7), n_tasks=st.integers(1, 30), width=st.integers(1, 12), depth=st.integers(0, 12),
       grid=st.booleans(), seed=st.integers(0, 2**32 - 1))
def test_visit_property_starts_on_one_edge_targets_on_the_floor(n_agents, n_tasks, width, depth, grid, seed):
    """Over random sizes: the agents start evenly along x = 0 (on cells under ``grid``), ordered from y = 0 to the
    far corner; the targets lie on the floor, on distinct free cells under ``grid``; the same seed draws the same
    instance. A config the grid cannot hold is refused instead."""
    depth = depth + 0.5 * (not grid)                  # a non-integer depth off the grid
    kw = dict(n_agents=n_agents, n_tasks=n_tasks, arena=[float(width), float(depth) or 1.0, 1.0], grid=grid)
    cells = (width + 1) * (int(kw["arena"][1]) + 1)
    if grid and (n_agents > int(kw["arena"][1]) + 1 or n_tasks > cells - n_agents):
        with pytest.raises(ConfigError):
            resolve_config("visit", **kw)
        return
    s = draw(seed, **kw)
    y = s.agent_pos[:, 1]
    assert (s.agent_pos[:, [0, 2]] == 0).all() and (np.diff(y) > 0).all()
    if n_agents > 1:
        assert y[0] == 0 and y[-1] == pytest.approx(kw["arena"][1] if not grid else int(kw["arena"][1]))
        spacing = np.diff(y)
        assert spacing.max() - spacing.min() <= (1 + 1e-9 if grid else 1e-9)
    assert (s.task_pos[:, 2] == 0).all() and (s.task_pos[:, :2] >= 0).all()
    assert (s.task_pos[:, :2] <= np.array(kw["arena"][:2])).all()
    if grid:
        assert (s.agent_pos == np.round(s.agent_pos)).all() and (s.task_pos == np.round(s.task_pos)).all()
        taken = {tuple(p) for p in s.task_pos[:, :2].tolist()}
        assert len(taken) == n_tasks and not taken & {tuple(p) for p in s.agent_pos[:, :2].tolist()}
    again = draw(seed, **kw)
    assert np.array_equal(again.task_pos, s.task_pos) and np.array_equal(again.agent_pos, s.agent_pos)


def test_the_environment_draws_one_visit_instance_per_seed():
    """Determinism through the environment: ``reset(seed)`` draws the same instance whatever the channel, another
    seed another instance."""
    a = TaskAllocEnv("visit")
    b = pettingzoo.make("parallel", "taskalloc/TaskAlloc-v0", scenario="visit", loss_model="gilbert_elliott_rho",
                        message_loss=0.4)
    a.reset(seed=3)
    b.reset(seed=3)
    assert np.array_equal(a.scenario.task_pos, b.unwrapped.scenario.task_pos)
    a.reset(seed=4)
    assert not np.array_equal(a.scenario.task_pos, b.unwrapped.scenario.task_pos)
    assert visit_starts(a.config).tolist() == a.scenario.agent_pos.tolist()


def test_an_ideal_visit_episode_serves_every_target_with_grid_moves():
    """CBBA on a visit instance: every target served, conflict-free, and the longest flight is a whole number of
    grid moves (Manhattan travel between cells)."""
    env = TaskAllocEnv("visit")
    allocation = rollout(env, make_policy("cbba"), seed=0)
    assert allocation.completion == 1.0 and not allocation.conflicts
    assert allocation.max_travel == round(allocation.max_travel) > 0


# -- bad parameters: one line each, when the config is built ------------------------------------------------------
@pytest.mark.parametrize("overrides, field", [
    ({"task_mix": [{"count": 10, "agents": 1}]}, "'task_mix'"),
    ({"prerequisites": {"chains": 1, "length": 2}}, "'prerequisites'"),
    ({"agent_types": ["A", "B"]}, "'agent_types'"),
    ({"n_tasks": 358}, "'n_tasks'"),                                 # 19 × 19 cells − 4 starts = 357
    ({"n_agents": 20, "n_tasks": 5}, "'n_agents'"),                  # 19 cells along the edge
])
def test_what_the_visit_generator_cannot_honour_is_one_line(overrides, field):
    with pytest.raises(ConfigError, match=field) as error:
        resolve_config("visit", **overrides)
    assert "\n" not in str(error.value)


def test_grid_cells_belong_to_the_visit_generator():
    with pytest.raises(ConfigError, match=r"'grid': got True; allowed: false with generator uniform") as error:
        resolve_config("default", grid=True)
    assert "\n" not in str(error.value)
    assert resolve_config("visit", n_tasks=357).n_tasks == 357      # exactly the free cells


def test_a_generator_may_register_a_check_and_drop_it_again(monkeypatch):
    monkeypatch.setitem(GENERATORS, "uniform", GENERATORS["uniform"])
    monkeypatch.setitem(CHECKS, "uniform", CHECKS["uniform"])

    def refuse_large(cfg):
        if cfg.n_agents > 3:
            raise ConfigError("config field 'n_agents': got many; allowed: at most 3")
    register_generator("small_only", GENERATORS["uniform"], refuse_large)
    try:
        assert resolve_config(generator="small_only", n_agents=3, agents_per_task=1).n_agents == 3
        with pytest.raises(ConfigError, match="at most 3"):
            resolve_config(generator="small_only", n_agents=4, agents_per_task=1)
        register_generator("small_only", GENERATORS["uniform"])           # no check: every config accepted
        assert resolve_config(generator="small_only", n_agents=4).n_agents == 4
        with pytest.raises(TypeError, match="must be callable"):
            register_generator("small_only", GENERATORS["uniform"], check="no")
    finally:
        GENERATORS.pop("small_only", None)
        CHECKS.pop("small_only", None)


# -- Manhattan travel ------------------------------------------------------------------------------------------------
def test_manhattan_travel_is_the_grid_walk_and_euclidean_the_straight_flight():
    """From (0, 0, 0) to (3, 4, 0) and on to (3, 4, 2): 5 + 2 flown straight, 7 + 2 along the grid; the travel times,
    costs (γ = 1) and the allocation's flight lengths all follow the metric."""
    s = Scenario.from_entities([Agent((0.0, 0.0, 0.0), 1.0)],
                               [Task((3.0, 4.0, 0.0), 100.0, 0.0, np.inf, 0.0), Task((3.0, 4.0, 2.0), 100.0, 0.0,
                                                                                      np.inf, 0.0)],
                               time_discount=0.0, distance_discount=1.0)
    for metric, legs in (("euclidean", (5.0, 2.0)), ("manhattan", (7.0, 2.0))):
        model = ScoringModel(s, travel_metric=metric)
        schedule = model.schedule(0, [0, 1])
        assert schedule.arrival.tolist() == [legs[0], sum(legs)]
        assert schedule.cost.tolist() == list(legs)
        env = TaskAllocEnv(s, travel_metric=metric)
        allocation = rollout(env, make_policy("cbba"), seed=0)
        assert allocation.max_travel == sum(legs) and allocation.score == 200.0 - sum(legs)


def test_the_distance_observation_stays_in_its_space_under_manhattan_travel():
    """Positions at both corners of ±arena: the Manhattan distance over the arena diagonal would exceed the
    observation's bound (2); the observation holds it there (under euclidean travel the bound never binds)."""
    s = Scenario.from_entities([Agent((-1.0, -1.0, -1.0), 1.0)], [Task((1.0, 1.0, 1.0), 100.0, 0.0, np.inf, 0.0)],
                               time_discount=0.0, distance_discount=0.0)
    env = TaskAllocEnv(s, travel_metric="manhattan")
    observations, _ = env.reset(seed=0)
    assert env.observation_space("uav_0").contains(observations["uav_0"])
    layout = env.unwrapped.observation_layout
    assert observations["uav_0"]["observation"][layout.own_size + layout.task_column("distance")] == RELATIVE_BOUND
