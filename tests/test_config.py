"""Configuration: defaults from the sources (thesis §3.3.2; docs/configuration.md), YAML scenarios, and bad input
naming the offending field; infeasible requirements are reported by ``Scenario.infeasible_tasks``, not raised."""

from __future__ import annotations

import re

import numpy as np
import pytest
import yaml
from helpers import agent, build, task

from taskalloc_env import ConfigError, TaskAllocConfig, TaskAllocEnv, generate, load_config, resolve_config
from taskalloc_env.config import round_bound, to_mapping


def test_spec_defaults():
    """The default of every named option (docs/configuration.md; distance_cost: docs/decisions.md)."""
    cfg = TaskAllocConfig()
    assert cfg.prereq_mode == "all_have_bid"
    assert cfg.prereq_timing == "conservative"
    assert cfg.conflict_policy == "first_L_paid"
    assert cfg.require_known_capacity is False
    assert cfg.release_order == "bundle"
    assert cfg.cbba_table == "canonical"
    assert cfg.task_quitting is False and cfg.delta == 1
    assert cfg.reset_on == "additions"
    assert cfg.quit_block == "until_joined"      # the article's rule (docs/decisions.md)
    assert cfg.distance_cost == "leg" and cfg.bid_warping and cfg.outbid_ties == "strict"
    assert cfg.reward_time == "arrival" and cfg.marginal_gain == "rescore"
    assert cfg.edge_rule == "dist" and cfg.comm_range is None
    assert cfg.reward_split == "per_agent"
    assert cfg.units == "km_min"


def test_default_scenario_is_the_thesis_setup():
    """Thesis §3.3.2: 10 agents, 20 tasks, 5 × 5 × 2 km, 20 m/s, c̄ = 100, λ = γ = 0.8, windows and durations 5."""
    cfg = load_config("default")
    assert (cfg.n_agents, cfg.n_tasks) == (10, 20)
    assert cfg.arena == (5.0, 5.0, 2.0)
    assert cfg.speed == 20.0 and cfg.speed_internal == pytest.approx(1.2)      # 20 m/s = 1.2 km/min
    assert cfg.reward == 100.0 and cfg.time_discount == 0.8 and cfg.distance_discount == 0.8
    assert cfg.window == 5.0 and cfg.duration == 5.0
    s = generate(cfg, np.random.default_rng(0))
    assert np.all(s.agent_pos[:, 2] == 0), "agents start on the floor"
    assert np.all((s.task_pos >= 0) & (s.task_pos <= np.array([5.0, 5.0, 2.0])))
    np.testing.assert_allclose(s.task_end - s.task_start, 5.0)


@pytest.mark.parametrize("name", ["default", "train_small"])
def test_shipped_scenarios_load_and_run(name):
    cfg = load_config(name)
    env = TaskAllocEnv(cfg)
    env.reset(seed=0)
    assert env.config == cfg


def test_units_raw_keeps_the_speed():
    """Our unit reading: ``km_min`` converts 20 m/s to 1.2 km/min; ``raw`` uses the number as given."""
    assert TaskAllocConfig(units="raw", speed=3.0).speed_internal == 3.0
    assert TaskAllocConfig(speed=10.0).speed_internal == pytest.approx(0.6)


def test_round_trip_through_a_mapping(tmp_path):
    cfg = resolve_config({"n_agents": 4, "n_tasks": 6, "agent_types": ["A", "B"],
                          "task_mix": [{"count": 4, "equipment": ["A", "B"]}, {"count": 2, "agents": 1}],
                          "prerequisites": {"chains": 1, "length": 2}})
    path = tmp_path / "mine.yaml"
    path.write_text(yaml.safe_dump(to_mapping(cfg)))
    assert load_config(path) == cfg
    assert cfg.replace(n_tasks=6) == cfg


def test_round_bound_formula():
    """Our round bound (docs/decisions.md): T_max = 10 · max(N_m, N_n · max L_j) · D."""
    assert round_bound(20, 10, 4, 1) == 10 * 40
    assert round_bound(20, 3, 2, 3) == 10 * 20 * 3


# -- bad input names the field --------------------------------------------------------------------------------
BAD = [
    ({"n_agentz": 3}, "n_agentz"),
    ({"n_agents": -1}, "n_agents"),
    ({"n_tasks": 0}, "n_tasks"),
    ({"agents_per_task": 0}, "agents_per_task"),
    ({"agents_per_task": [1, -2]}, "agents_per_task"),
    ({"speed": -20.0}, "speed"),
    ({"window": 0}, "window"),
    ({"distance_cost": "euclid"}, "distance_cost"),
    ({"cbba_table": "choi"}, "cbba_table"),
    ({"prereq_mode": "some"}, "prereq_mode"),
    ({"release_order": "random"}, "release_order"),
    ({"consensus": "async"}, "consensus"),
    ({"task_quitting": "yes"}, "task_quitting"),
    ({"delta": -1}, "delta"),
    ({"arena": [5.0, 5.0]}, "arena"),
    ({"n_tasks": 5, "task_mix": [{"count": 2}, {"count": 2}], "agent_types": ["A"]}, "task_mix"),
    ({"n_tasks": 2, "agent_types": ["A"], "task_mix": [{"count": 2, "equipment": ["B"]}]}, "task_mix.equipment"),
    ({"n_tasks": 2, "task_mix": [{"count": 2, "equipment": ["A"]}]}, "task_mix.equipment"),
    ({"n_tasks": 2, "task_mix": [{"count": 2, "colour": "red"}]}, "task_mix.colour"),
    ({"n_tasks": 1, "task_mix": [{"count": -1}, {"count": 2}]}, "task_mix.count"),
    ({"n_agents": 4, "agent_types": ["A", "B"], "agent_type_counts": [1, 2]}, "agent_type_counts"),
    ({"n_tasks": 4, "prerequisites": {"chains": 2, "length": 3}}, "prerequisites"),
    ({"prerequisites": {"chains": 1, "depth": 2}}, "prerequisites.depth"),
]


@pytest.mark.parametrize("values, field", BAD, ids=[f for _, f in BAD])
def test_bad_config_raises_config_error_naming_the_field(values, field):
    with pytest.raises(ConfigError, match=re.escape(field)):
        resolve_config(values)


@pytest.mark.parametrize("values, field", BAD[:4], ids=[f for _, f in BAD[:4]])
def test_bad_config_through_the_environment(values, field):
    with pytest.raises(ConfigError, match=field):
        TaskAllocEnv(**values)


def test_bad_yaml_file(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("n_agents: 3\nspeeed: 20\n")
    with pytest.raises(ConfigError, match="speeed"):
        load_config(path)
    with pytest.raises(ConfigError, match="no_such_scenario"):
        load_config("no_such_scenario")


def test_config_errors_are_caught_as_value_errors_by_callers():
    """Code that guards a call with ``except ValueError`` (as argparse-style callers and the env's users do) sees a
    bad config as a ValueError that names the field and the allowed values."""
    with pytest.raises(ValueError, match=r"'n_agents': got 0; allowed: an integer >= 1") as info:
        TaskAllocConfig(n_agents=0)
    assert isinstance(info.value, ConfigError)


# -- infeasible requirements are reported, not raised ----------------------------------------------------------
def test_infeasible_requirements_are_reported():
    """A task needing three A agents when only two exist, and one needing two B agents when none exist: the scenario
    builds and the environment runs; ``infeasible_tasks`` names both with a reason."""
    agents = [agent(0, equipment=("A",)), agent(1, equipment=("A",)), agent(2, equipment=("C",))]
    tasks = [task(1, agents=3, equipment=("A", "A", "A")), task(2, agents=2, equipment=("B", "B")), task(3),
             task(1.5, agents=2, equipment=("A", "C"))]
    s = build(agents, tasks, equipment_names=("A", "B", "C"))
    report = s.infeasible_tasks()
    assert set(report) == {0, 1}
    assert all(isinstance(reason, str) and reason for reason in report.values())
    env = TaskAllocEnv(scenario=s)
    env.reset(seed=0)
    too_big = build([agent(0), agent(1)], [task(1, agents=3), task(2)])
    assert set(too_big.infeasible_tasks()) == {0}


def test_generated_infeasible_mix_is_reported():
    cfg = resolve_config({"n_agents": 3, "n_tasks": 2, "agent_types": ["A", "B"], "agent_type_counts": [1, 2],
                          "task_mix": [{"count": 1, "equipment": ["A", "A"]}, {"count": 1, "equipment": ["A", "B"]}]})
    s = generate(cfg, np.random.default_rng(0))
    assert set(s.infeasible_tasks()) == {0}
    TaskAllocEnv(cfg).reset(seed=0)


def test_equipment_items_must_match_required_agents():
    """|te_j| = L_j (thesis §3.1.3): with fewer items than agents the slot rule of ``groups.admit`` (a newcomer must
    fill an unmet item) could never fill the group, so such tasks are refused, naming the field and the rule."""
    with pytest.raises(ConfigError, match=r"task_mix\.agents"):
        resolve_config({"n_agents": 4, "n_tasks": 1, "agent_types": ["A"],
                        "task_mix": [{"count": 1, "agents": 3, "equipment": ["A"]}]})
    with pytest.raises(ValueError, match=r"\|te_j\| = L_j"):
        build([agent(0.5 * i, equipment=("A",)) for i in range(4)], [task(1, agents=3, equipment=("A",))])
    fine = build([agent(0.5 * i, equipment=("A",)) for i in range(4)], [task(1, agents=3, equipment=("A",) * 3)])
    assert fine.infeasible_tasks() == {}


def test_fixed_scenario_and_contradicting_counts():
    s = build([agent(0), agent(1)], [task(1)])
    with pytest.raises(ValueError, match="n_agents"):
        TaskAllocEnv(scenario=s, n_agents=3)
