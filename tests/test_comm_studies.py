"""The communication studies: δ in policy names, connectivity marks and reference pairing in the runner, the links
figure, the robustness command under message loss, drop-out against never-existed with its release timing, the
network strategies of the benchmark (small budgets throughout)."""

from __future__ import annotations

import numpy as np
import pytest

from taskalloc.evaluation import dropout, experiment_files, experiment_reports, experiments, figures, robustness
from taskalloc.evaluation.episodes import Episode, _env, run_episode
from taskalloc.evaluation.report import cell_text, values
from taskalloc.policies import make_policy, rollout
from taskalloc_env import TaskAllocEnv, resolve_config


# -- policy names with parameters ----------------------------------------------------------------------------------
def test_policy_names_carry_the_quit_threshold():
    policy = make_policy("cbga+tq:delta=3")
    assert policy.name == "CBGA+TQ" and policy.env_overrides == {"task_quitting": True, "delta": 3}
    assert make_policy("CBGABI:delta=0").env_overrides == {"task_quitting": True, "delta": 0}
    plain = make_policy("cbga+tq")                  # no δ in the name: δ is the config's (default 1), not pinned
    assert plain.quit_threshold is None and plain.env_overrides == {"task_quitting": True}
    assert resolve_config("default").delta == 1
    for bad in ("cbga:delta=2", "cbga+tq:delta=x", "cbga+tq:gamma=1", "cbga+tq:delta"):
        with pytest.raises(ValueError):
            make_policy(bad)


def test_a_series_per_delta_reaches_the_environment():
    cfg = resolve_config("default", n_agents=4, n_tasks=6, agents_per_task=2)
    assert _env("cbga+tq:delta=4", cfg).config.delta == 4
    assert _env("cbga+tq:delta=0", cfg).config.delta == 0
    row = run_episode(Episode("cbga+tq:delta=4", cfg, 0))
    assert row["solver"] == "CBGA+TQ" and row["converged"]


# -- runner: marks, reference pairing, yes/no metrics ---------------------------------------------------------------
def test_yes_no_metrics_read_from_csv_and_show_as_shares():
    rows = [{"seed": 0, "connected": "True", "converged": "True"}, {"seed": 1, "connected": "False",
                                                                    "converged": "True"}]
    assert values(rows, "connected").tolist() == [1.0, 0.0]
    assert cell_text(rows, "connected") == "50 %"


def test_marks_find_the_first_point_reaching_the_share():
    points = [experiment_files.Point(str(r), r, {"comm_range": r}) for r in (1.0, 2.0, 3.0)]
    rows = [{"point": str(r), "series": "A", "seed": k, "connected": k < share * 4, "converged": True}
            for r, share in ((1.0, 0.0), (2.0, 0.5), (3.0, 1.0)) for k in range(4)]
    exp = experiment_files.Experiment(
        name="x", title="x", source="", scenario="default", overrides={}, xlabel="r", points=points,
        series=[experiment_files.Series("A", "cbga", {})], baseline=None, metrics=["score"], episodes=4, headline=[],
        published="", checks=[], quick_points=points, quick_episodes=1, raw={},
        marks=[experiment_files.Mark("connected", 0.5, "half"), experiment_files.Mark("connected", 1.0, "all"),
               experiment_files.Mark("fully_connected", 0.5, "never")])
    found = experiment_reports.mark_points(exp, experiment_reports.cells_of(rows), points)
    assert [(m.label, p.label if p else None) for m, p in found] == [("half", "2.0"), ("all", "3.0"),
                                                                     ("never", None)]


def test_reference_pairing_and_marks_in_a_run(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text("""
name: tiny
title: tiny loss sweep
scenario: default
overrides: {n_agents: 4, n_tasks: 6, agents_per_task: 2, start_time_range: [0.0, 30.0]}
sweep: {field: message_loss, label: "loss", values: [0.0, 0.3]}
series: [cbga]
metrics: [score, rounds, converged, connected]
episodes: 3
marks: [{metric: connected, share: 0.5}]
reference: {point: "0.0", metrics: [score, rounds]}
""")
    exp = experiment_files.load_experiment(path)
    assert exp.reference.point.label == "0.0" and exp.marks[0].metric == "connected"
    target = experiments.run_experiment(exp, tmp_path / "out", jobs=1, progress=False)
    table = (target / "table.md").read_text()
    assert "Paired against loss = 0.0 (rounds" in table and "reference" in table and "[95 % CI]" in table
    assert "Marked in the plots" in table and "from loss = 0.0" in table
    assert "100 %" in table                                            # converged, as a share
    for name in ("delta_score.png", "delta_rounds.png", "connected.png"):
        assert (target / name).stat().st_size > 0
    experiments.report_experiment(exp, tmp_path / "out", docs=None)   # the CSV (True/False strings) reads back
    assert (target / "table.md").read_text() == table


def test_bad_marks_and_references_fail_early(tmp_path):
    base = "name: x\nseries: [cbga]\nsweep: {field: message_loss, values: [0.0, 0.1]}\n"
    for extra, message in (("marks: [{metric: score}]\n", "yes/no metric"),
                           ("marks: [{metric: connected, share: 2}]\n", "share"),
                           ("reference: {point: '0.5'}\n", "matches no sweep point"),
                           ("reference: {point: '0.0', metrics: [nope]}\n", "unknown metric")):
        path = tmp_path / "x.yaml"
        path.write_text(base + extra)
        with pytest.raises(ValueError, match=message):
            experiment_files.load_experiment(path)


def test_data_per_agent_per_assignment_divides_by_the_required_assignments():
    cfg = resolve_config("default", n_agents=5, n_tasks=6, agents_per_task=2)
    row = run_episode(Episode("cbga", cfg, 1))
    assert row["data_per_agent_per_assignment"] == pytest.approx(row["data_received_per_agent"] / 12)


def test_new_experiment_files_are_in_the_suite():
    names = set(experiments.experiment_paths([], every=True))
    assert {"fig4_6_7_range", "fig4_8_10_data", "fig5_10_delta_range", "comm_loss", "comm_dropout"} <= names
    assert experiment_files.load_experiment("fig4_6_7_range").marks
    assert experiment_files.load_experiment("comm_loss").reference.point.label == "0.0"


# -- the links figure ------------------------------------------------------------------------------------------------
def test_links_figure_draws_one_instance(tmp_path):
    seed = figures.pick_seed()
    made = figures.links(tmp_path, seed, panels=figures.PANELS[1:2])
    name, figs = made[0]
    assert (tmp_path / name).stat().st_size > 10_000
    assert figs["seed"] == seed and figs["groups"] == 2                      # two groups at r = 2 (Fig 4.3)


# -- robustness under message loss ---------------------------------------------------------------------------------
def test_robustness_runs_every_algorithm_and_checks_each_episode():
    verdicts = robustness.robustness(scenarios=3, seed=1, loss=0.2, jobs=1)
    assert [v["case"][0] for v in verdicts] == ["cbba"] * 3 + ["cbga"] * 3 + ["cbgabi"] * 3
    assert all(v["case"][1]["message_loss"] == 0.2 for v in verdicts)
    assert all(v["case"][1]["agents_per_task"] == 1 for v in verdicts[:3])
    assert not robustness.failures(verdicts)
    text = robustness.report(verdicts)
    assert "CBGABI (mixed L_j)" in text and "3 (100.0 %)" in text


def test_robustness_draws_sizes_in_range_and_mixed_l():
    cases = robustness.cases(200, 0, 0.2)
    sizes = [(kw["n_agents"], kw["n_tasks"]) for _, kw, _ in cases]
    assert min(n for n, _ in sizes) == 3 and max(n for n, _ in sizes) == 10
    assert min(m for _, m in sizes) == 4 and max(m for _, m in sizes) == 20
    mixed = [kw for name, kw, _ in cases if name != "cbba" and isinstance(kw.get("agents_per_task"), list)]
    assert len(mixed) > 100


def test_group_conflicts_ignore_agents_that_cannot_hear_each_other():
    env = TaskAllocEnv(n_agents=4, n_tasks=5, agents_per_task=1, comm_range=0.01)
    allocation = rollout(env, make_policy("cbba"), seed=0)
    assert allocation.converged and allocation.conflicts                     # isolated agents duplicate work
    assert robustness.group_conflicts(env.unwrapped.protocol) == 0           # but no group holds a conflict


# -- drop-out against never-existed ----------------------------------------------------------------------------------
def test_without_agent_removes_only_its_row():
    env = TaskAllocEnv(n_agents=5, n_tasks=4, agents_per_task=1)
    env.reset(seed=3)
    s = env.unwrapped.scenario
    r = dropout.without_agent(s, 2)
    assert r.n_agents == 4 and np.array_equal(r.agent_pos, np.delete(s.agent_pos, 2, axis=0))
    assert np.array_equal(r.task_pos, s.task_pos) and np.array_equal(r.task_agents, s.task_agents)


@pytest.mark.parametrize("name", ["cbba", "cbga", "cbgabi"])
def test_a_failed_agents_bids_are_released_within_timeout_plus_diameter(name):
    for seed in range(3):
        row = dropout.run_seed((name, seed, 3, "default"))
        assert row["release_rounds"] is not None, row
        assert 0 <= row["release_rounds"] <= row["bound"], row
        assert row["converged"]
        assert row["agent"] == seed % 10


def test_release_timing_on_a_range_limited_network():
    cfg = resolve_config("default", agents_per_task=1, comm_range=2.5, dropout_schedule=[[1, 2]])
    for seed in range(3):
        env = TaskAllocEnv(cfg, **make_policy("cbba").env_overrides)
        allocation, release = dropout.run_with_failure(env, make_policy("cbba"), seed, 1)
        assert allocation.converged and release.failed_at == 2
        assert release.rounds is not None and release.rounds <= release.bound


def test_dropout_command_prints_the_paired_table(capsys):
    assert dropout.main(["--episodes", "2", "--jobs", "1", "--algorithms", "cbba"]) == 0
    out = capsys.readouterr().out
    assert "Δ fails − never" in out and "within bound" in out and "CBBA (L_j = 1)" in out


# -- benchmark: network strategies against perfect links -------------------------------------------------------------
def test_bench_strategies_reports_every_strategy_against_perfect(capsys):
    from benchmarks.bench_env import STRATEGIES, bench_strategies

    figs = bench_strategies(seeds=1, scenario="train_small")
    assert list(figs) == list(STRATEGIES) and next(iter(figs)) == "perfect"
    assert all(f["seconds"] > 0 and f["rounds"] > 0 for f in figs.values())
    assert "(x1.00)" in capsys.readouterr().out
