"""The experiment runner: paired seeds, statistics, non-converged episodes, the quick run and its outputs."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from scipy import stats as sps

from taskalloc.evaluation import experiment_files, experiment_reports, experiments
from taskalloc.evaluation.episodes import Episode, check_pairing, fingerprint, run_episode, run_episodes
from taskalloc.evaluation.stats import (
    ci95_half,
    mean_sd,
    paired,
    paired_t_pvalue,
    share_better,
    share_tied,
    wilcoxon_pvalue,
)
from taskalloc_env import ConfigError, TaskAllocEnv, resolve_config, resources

SMALL = {"n_agents": 4, "n_tasks": 6, "agents_per_task": 2, "start_time_range": [0.0, 30.0]}


# -- statistics ----------------------------------------------------------------------------------------------------
def test_mean_sd_is_sample_sd():
    x = [3.0, 5.0, 10.0]
    assert mean_sd(x) == pytest.approx((6.0, np.sqrt(((3 - 6) ** 2 + (5 - 6) ** 2 + (10 - 6) ** 2) / 2)))
    assert mean_sd([4.0]) == (4.0, 0.0)


def test_paired_t_matches_hand_computation_and_scipy():
    a = np.array([10.0, 12.0, 9.0, 15.0, 11.0])
    b = np.array([8.0, 11.0, 9.5, 12.0, 10.0])
    d = a - b
    t = d.mean() / (d.std(ddof=1) / np.sqrt(d.size))
    by_hand = 2 * sps.t.sf(abs(t), d.size - 1)
    assert paired_t_pvalue(a, b) == pytest.approx(by_hand)
    assert paired_t_pvalue(a, b) == pytest.approx(sps.ttest_rel(a, b).pvalue)
    # an unpaired test on the same numbers gives another answer: pairing matters
    assert paired_t_pvalue(a, b) != pytest.approx(sps.ttest_ind(a, b).pvalue)


def test_the_95_interval_matches_scipy_along_any_axis():
    x = np.array([[1.0, 4.0], [2.0, 8.0], [4.0, 5.0]])
    low, high = sps.t.interval(0.95, 2, loc=x[:, 1].mean(), scale=sps.sem(x[:, 1]))
    assert ci95_half(x[:, 1]) == pytest.approx((high - low) / 2)
    np.testing.assert_allclose(ci95_half(x, axis=0), [ci95_half(x[:, 0]), ci95_half(x[:, 1])])
    assert ci95_half([3.0]) == 0.0 and ci95_half(x[:1], axis=0).tolist() == [0.0, 0.0]


def test_wilcoxon_and_shares():
    rng = np.random.default_rng(1)
    a, b = rng.normal(10, 1, 30), rng.normal(9.5, 1, 30)
    assert wilcoxon_pvalue(a, b) == pytest.approx(sps.wilcoxon(a - b).pvalue)
    assert share_better([3, 2, 1, 5], [1, 2, 3, 4]) == 0.5
    assert share_tied([3, 2, 1, 5], [1, 2, 3, 4]) == 0.25


def test_identical_samples_give_no_evidence():
    x = [1.0, 2.0, 3.0]
    assert paired_t_pvalue(x, x) == 1.0
    assert wilcoxon_pvalue(x, x) == 1.0
    pc = paired(x, x)
    assert (pc.mean_diff, pc.ratio, pc.better, pc.tied) == (0.0, 1.0, 0.0, 1.0)


# -- paired evaluation ---------------------------------------------------------------------------------------------
def test_same_seed_gives_the_same_instance_to_every_solver():
    cfg = resolve_config("default", **SMALL)
    rows = [run_episode(Episode(s, cfg, seed)) for s in ("cbga", "cbgabi", "random", "sgama") for seed in (3, 4)]
    by_seed = {seed: {r["instance"] for r in rows if r["seed"] == seed} for seed in (3, 4)}
    assert len(by_seed[3]) == 1 and len(by_seed[4]) == 1 and by_seed[3] != by_seed[4]
    env = TaskAllocEnv(cfg)
    env.reset(seed=3)
    assert by_seed[3] == {fingerprint(env.unwrapped.scenario)}
    assert check_pairing(rows, []) == []
    assert check_pairing([*rows, {**rows[0], "instance": "other"}], [])   # a broken pair is reported


def test_parallel_run_equals_serial_run():
    cfg = resolve_config("default", **SMALL)
    runs = [Episode(s, cfg, seed, (("series", s),)) for s in ("cbga", "cbga+tq") for seed in range(3)]
    assert run_episodes(runs, jobs=2, progress=False) == run_episodes(runs, jobs=1, progress=False)


def test_centralised_rows_have_no_protocol_figures():
    row = run_episode(Episode("sgama", resolve_config("default", **SMALL), 0))
    assert row["solver"] == "SGAMA" and row["messages"] is None and row["comm_steps"] is None
    assert row["score"] > 0


# -- runner --------------------------------------------------------------------------------------------------------
def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "exp.yaml"
    path.write_text(text)
    return path


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_non_converged_episodes_are_counted_and_kept(tmp_path):
    path = _write(tmp_path, """
name: capped
title: capped rounds
scenario: default
overrides: {n_agents: 4, n_tasks: 6, agents_per_task: 2, max_rounds: 1}
series: [cbga, cbgabi]
baseline: CBGA
episodes: 3
""")
    exp = experiment_files.load_experiment(path)
    target = experiments.run_experiment(exp, tmp_path / "out", jobs=1, progress=False)
    rows = _rows(target / "episodes.csv")
    assert len(rows) == 6                                           # nothing dropped
    bad = sum(r["converged"] == "False" for r in rows)
    assert bad > 0
    table = (target / "table.md").read_text()
    assert f"{bad} of 6 episodes" in table
    assert " nc)" in table


@pytest.mark.slow
def test_quick_run_writes_every_output_and_report_rebuilds_it(tmp_path):
    out = tmp_path / "out"
    docs = tmp_path / "results.md"
    docs.write_text("# Results\n\nHand-written text stays.\n\n<!-- results:suite:start -->\n"
                    "<!-- results:suite:end -->\n")
    argv = ["run", "fig5_16_l4", "--quick", "--out", str(out), "--jobs", "1", "--no-progress", "--docs", str(docs)]
    assert experiments.main(argv) == 0
    target = out / "fig5_16_l4"
    for name in ("episodes.csv", "table.md", "config.yaml", "run.json", "score.png", "headline_10.png"):
        assert (target / name).stat().st_size > 0, name
    exp = experiment_files.load_experiment("fig5_16_l4")
    rows = _rows(target / "episodes.csv")
    assert len(rows) == len(exp.quick_points) * len(exp.series) * exp.quick_episodes
    assert {r["solver"] for r in rows} == {"CBGA", "CBGA+TQ", "CBGA+TB", "CBGABI", "SGAMA"}
    info = json.loads((target / "run.json").read_text())
    assert info["packages"]["numpy"] and info["episodes_total"] == len(rows)
    text = docs.read_text()
    assert "Hand-written text stays." in text and "<!-- results:fig5_16_l4:start -->" in text
    table = (target / "table.md").read_text()
    with pytest.raises(ConfigError, match="already holds the results of fig5_16_l4"):
        experiments.main(["report", "fig5_16_l4", "--out", str(out), "--docs", str(docs)])
    assert experiments.main(["report", "fig5_16_l4", "--out", str(out), "--docs", str(docs), "--overwrite"]) == 0
    assert (target / "table.md").read_text() == table               # the CSV holds everything the report needs
    assert docs.read_text().count("<!-- results:fig5_16_l4:start -->") == 1


def test_every_experiment_file_loads_and_covers_the_published_experiments():
    names = {experiment_files.load_experiment(name).name for name in resources.names("experiments")}
    for required in ("fig3_11_cbba_vs_cbga", "fig3_17_sgama_agents", "fig5_11_l_sweep", "fig5_16_l4",
                     "fig5_7_13_all_l10", "fig3_23_heterogeneous", "fig3_25_prerequisites", "optimality_gap"):
        assert required in names
    assert experiment_files.load_experiment("fig5_16_l4").episodes == 100


def test_bad_experiment_files_fail_early(tmp_path):
    with pytest.raises(ValueError, match="unknown keys"):
        experiment_files.load_experiment(_write(tmp_path, "name: x\nsereis: [cbga]\n"))
    with pytest.raises(ValueError, match="not a series label"):
        experiment_files.load_experiment(_write(tmp_path, "name: x\nseries: [cbga]\nbaseline: CBBA\n"))
    with pytest.raises(ValueError, match="both set"):
        experiment_files.load_experiment(_write(tmp_path, """
name: x
sweep: {field: agents_per_task, values: [1, 2]}
series: [{solver: cbga, overrides: {agents_per_task: 3}}]
"""))


def test_checks_test_the_claim_on_paired_cells():
    points = [experiment_files.Point("10", 10, {"n_agents": 10})]
    rows = [{"point": "10", "series": s, "seed": k, "score": v, "converged": True}
            for k in range(8) for s, v in (("A", 100 + k + (k % 3)), ("B", 90 + k))]
    cells = experiment_reports.cells_of(rows)

    def verdict(test: str, **kw) -> str:
        return experiment_reports.evaluate_check(experiment_files.Check("c", "A", "B", test, **kw), cells, points)[1]

    assert verdict("greater") == "yes"
    assert verdict("less") == "no"
    assert verdict("same") == "no"
    assert verdict("ratio_above", ratio=1.05) == "yes"
    assert verdict("ratio_above", ratio=1.5) == "no"
    check = experiment_files.Check("c", "A", "B", "greater", at=({"n_agents": 5},))
    assert experiment_reports.evaluate_check(check, cells, points)[1] == "n/a"


# -- δ reaches the quitting policies; grid sweeps and heat maps ------------------------------------------------------
def test_a_delta_sweep_reaches_the_quitting_policy():
    from taskalloc.evaluation import episodes
    from taskalloc.policies import CBGAPolicy

    assert CBGAPolicy(task_quitting=True).env_overrides == {"task_quitting": True}    # δ from the environment
    rounds = {}
    for delta in (0, 8):
        cfg = resolve_config("default", delta=delta)
        env = episodes._env("cbga+tq", cfg)
        assert env.config.delta == delta and env.config.task_quitting
        rounds[delta] = [run_episode(Episode("cbga+tq", cfg, seed))["rounds"] for seed in range(3)]
        policy = episodes.policy_for("cbga+tq")
        assert policy.delta == delta                        # the policy quits with the environment's δ
    assert sum(rounds[8]) > sum(rounds[0])                   # a longer wait before quitting: more rounds


def test_a_pinned_policy_may_not_overrule_a_swept_option(monkeypatch):
    from taskalloc.evaluation import episodes
    from taskalloc.policies import CBGAPolicy

    monkeypatch.setattr(episodes, "policy_for", lambda solver: CBGAPolicy(task_quitting=True, quit_threshold=2))
    assert episodes.policy_overrides("pinned", resolve_config("default")) == {"task_quitting": True, "delta": 2}
    with pytest.raises(ValueError, match="delta=3"):
        episodes.policy_overrides("pinned", resolve_config("default", delta=3))


def test_grid_sweep_heatmaps_and_comm_columns(tmp_path):
    path = _write(tmp_path, """
name: duo_grid
scenario: default
sweep: {grid: {n_agents: [2, 3], n_tasks: [3, 4]}, label: "N_n × N_m"}
series:
  - {solver: cbba, label: CBBA, overrides: {agents_per_task: 1}}
  - {solver: cbba-duo, label: duo, overrides: {agents_per_task: 1}}
  - {solver: cbga, label: CBGA, overrides: {agents_per_task: 2, reward: 150, reward_split: total}}
baseline: CBBA
metrics: [score, comm_steps, comm_steps_to_agreement]
episodes: 2
headline: ["3 × 4"]
heatmap: {baseline: CBBA, series: [duo, CBGA], difference: [CBGA, duo]}
""")
    exp = experiment_files.load_experiment(path)
    assert [p.label for p in exp.points] == ["2 × 3", "2 × 4", "3 × 3", "3 × 4"]
    assert exp.points[1].overrides == {"n_agents": 2, "n_tasks": 4}
    docs = tmp_path / "results.md"
    target = experiments.run_experiment(exp, tmp_path / "out", jobs=1, progress=False, docs=docs)
    for name in ("heatmap_duo_over_CBBA.png", "heatmap_CBGA_over_CBBA.png", "heatmap_CBGA_minus_duo.png"):
        assert (target / name).stat().st_size > 0
    rows, cols, maps = experiment_reports.heatmap_maps(exp, experiment_reports.cells_of(_rows(target / "episodes.csv")),
                                                exp.points)
    assert (rows, cols) == ([2, 3], [3, 4])
    np.testing.assert_allclose(maps["CBGA minus duo"], maps["CBGA over CBBA"] - maps["duo over CBBA"])
    block = docs.read_text()
    assert "duo over CBBA" in block and "comm steps (end) | comm steps (agreement)" in block
    assert "**Ours, score** (mean ± sd)" not in block          # the maps replace the per-point tables in the docs
    with pytest.raises(ValueError, match="grid of two fields"):
        experiment_files.load_experiment(_write(tmp_path,
                                                "name: x\nseries: [cbba]\nheatmap: {baseline: CBBA, series: []}"))


def test_a_heatmap_grid_takes_a_reference_point_but_no_marks(tmp_path):
    """The runner's two sets of keys together: heat maps over a grid, paired against one of its cells."""
    text = """
name: grid_reference
scenario: default
overrides: {agents_per_task: 2}
sweep: {grid: {n_agents: [3, 4], n_tasks: [3, 4]}}
series: [cbga, cbgabi]
baseline: CBGA
metrics: [score, comm_steps]
episodes: 2
heatmap: {baseline: CBGA, series: [CBGABI]}
reference: {point: "3 × 3", metrics: [score]}
"""
    exp = experiment_files.load_experiment(_write(tmp_path, text))
    assert exp.heatmap is not None and exp.reference.point.label == "3 × 3" and not exp.marks
    docs = tmp_path / "results.md"
    target = experiments.run_experiment(exp, tmp_path / "out", jobs=1, progress=False, docs=docs)
    assert (target / "heatmap_CBGABI_over_CBGA.png").stat().st_size > 0
    assert (target / "delta_score.png").stat().st_size > 0
    block = docs.read_text()
    assert "CBGABI over CBGA" in block and "paired against n_agents × n_tasks = 3 × 3" in block
    assert "Paired against n_agents × n_tasks = 3 × 3 (score" in (target / "table.md").read_text()
    with pytest.raises(ValueError, match="marks"):
        experiment_files.load_experiment(_write(tmp_path, text + "marks: [{metric: connected}]\n"))
