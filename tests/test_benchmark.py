"""The task suite v0 (``taskalloc_env.suite``) and ``taskalloc benchmark`` (``taskalloc.evaluation.benchmark``)."""

from __future__ import annotations

import csv
import json
import sys
import textwrap
from pathlib import Path

import numpy as np
import pettingzoo
import pytest

import taskalloc_env  # noqa: F401  (registers the suite's ids)
from taskalloc.cli import main as cli
from taskalloc.evaluation import benchmark, benchmark_stats
from taskalloc.evaluation.episodes import policy_for
from taskalloc.evaluation.seeds import DEMO_SEED_START, TEST_SEEDS, VALIDATION_SEED_START
from taskalloc.evaluation.suite_reference import load_reference
from taskalloc_env import suite
from taskalloc_env.errors import ConfigError

SLOW_IDS = {"taskalloc/Large-v0", "taskalloc/Async-v0"}       # a random episode takes 3–16 s there
USER_MODULE = textwrap.dedent('''
    import numpy as np


    class FirstBid:
        """Duck-typed: bids on the allowed task with the lowest index, else passes (no subclassing)."""

        def start(self, env, seed=None):
            self.seed = seed

        def act(self, observations, infos=None):
            return {agent: int(np.flatnonzero(obs["action_mask"])[-1] if obs["action_mask"][1:].any() else 0)
                    for agent, obs in observations.items()}


    def passes(observations):
        return {agent: 0 for agent in observations}


    def out_of_mask(observations):
        return {agent: len(obs["action_mask"]) + 3 for agent, obs in observations.items()}


    class FourAgentsOnly(FirstBid):
        def start(self, env, seed=None):
            if env.unwrapped.config.n_agents != 4:
                raise ValueError("trained on 4 agents")


    NOT_A_POLICY = 42
''')


@pytest.fixture()
def user_module(tmp_path, monkeypatch):
    (tmp_path / "suite_user_policy.py").write_text(USER_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "suite_user_policy"
    sys.modules.pop("suite_user_policy", None)
    policy_for.cache_clear()


def random_masked_episode(env_type: str, task_id: str, seed: int) -> float:
    """A uniform random masked episode of ``pettingzoo.make(env_type, task_id)``; the final team score."""
    env = pettingzoo.make(env_type, task_id)
    rng = np.random.default_rng(seed)
    if env_type == "parallel":
        observations, _ = env.reset(seed=seed)
        while env.agents:
            actions = {a: int(rng.choice(np.flatnonzero(o["action_mask"]))) for a, o in observations.items()}
            observations, _, _, _, _ = env.step(actions)
    else:
        env.reset(seed=seed)
        for _agent in env.agent_iter():
            obs, _, term, trunc, _ = env.last()
            env.step(None if term or trunc else int(rng.choice(np.flatnonzero(obs["action_mask"]))))
    return env.unwrapped.evaluate().score


@pytest.mark.parametrize("task_id", [pytest.param(t, marks=pytest.mark.slow) if t in SLOW_IDS else t
                                     for t in suite.TASKS])
def test_every_id_makes_resets_and_finishes_a_random_episode(task_id):
    for env_type in ("parallel", "aec"):
        score = random_masked_episode(env_type, task_id, suite.task(task_id).test_seeds[0])
        assert score > 0
    assert pettingzoo.make("parallel", task_id).unwrapped.config == suite.task(task_id).config()


def test_suite_ids_seeds_and_cards():
    ids = list(suite.TASKS)
    for name in ("Small", "Default", "Large", "Hetero", "TightWindows", "Range", "Lossy", "Delay", "Dropout",
                 "Async"):
        assert f"taskalloc/{name}-v0" in ids
    assert sum(i.startswith("taskalloc/Ladder") for i in ids) >= 3
    cfg = suite.task("taskalloc/Small-v0").config()
    assert (cfg.n_agents, cfg.n_tasks, cfg.agents_per_task) == (4, 8, (1, 2))
    cfg = suite.task("taskalloc/Large-v0").config()
    assert (cfg.n_agents, cfg.n_tasks, cfg.agents_per_task) == (50, 100, 4)
    others = {*TEST_SEEDS, *range(VALIDATION_SEED_START, VALIDATION_SEED_START + 1000)}
    for t in suite.TASKS.values():
        assert t.tests and t.source
        assert not set(t.test_seeds) & set(t.validation_seeds)
        assert not (set(t.test_seeds) | set(t.validation_seeds)) & others
        assert max(t.validation_seeds) < DEMO_SEED_START


def test_unknown_task_lists_the_suite(capsys):
    with pytest.raises(ConfigError, match=r"taskalloc/Small-v0.*taskalloc/Default-v0"):
        suite.task("taskalloc/Smal-v0")
    assert cli(["benchmark", "--policy", "random", "--out", "x", "--tasks", "Tiny"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "taskalloc/Async-v0" in err


def test_reference_covers_the_suite_on_its_seeds():
    reference = load_reference()["tasks"]
    assert set(reference) == set(suite.TASKS)
    for task_id, entry in reference.items():
        t = suite.task(task_id)
        assert entry["seeds"] == list(t.test_seeds)
        assert entry["solvers"] == {"random": "random", "normaliser": t.normaliser, "best_known": t.best_known}
        # the best-known value bounds every baseline's mean (exact: the optimum; LNS: the best we know), and the
        # normaliser beats random, otherwise the normalised scale would be inverted
        assert np.mean(entry["best_known"]) >= max(np.mean(entry["random"]), np.mean(entry["normaliser"])) - 1e-6
        if task_id == "taskalloc/Large-v0":           # the exception, which its card states
            assert np.mean(entry["normaliser"]) < np.mean(entry["random"]) and "inverted" in t.tests
        else:
            assert np.mean(entry["normaliser"]) > np.mean(entry["random"]), task_id


@pytest.mark.parametrize("task_id,solver,part", [
    ("taskalloc/Small-v0", "random", "random"), ("taskalloc/Default-v0", "cbgabi", "normaliser"),
    ("taskalloc/Small-v0", "exact", "best_known"),
    pytest.param("taskalloc/Default-v0", "lns", "best_known", marks=pytest.mark.slow),
    pytest.param("taskalloc/Async-v0", "acbba", "normaliser", marks=pytest.mark.slow)])
def test_reference_entries_reproduce(task_id, solver, part):
    from taskalloc.evaluation.suite_episodes import play_task
    entry = load_reference()["tasks"][task_id]
    rows = play_task(solver, task_id, entry["seeds"][:3])
    assert [r["score"] for r in rows] == entry[part][:3]
    assert [r["instance"] for r in rows] == entry["instances"][:3]


def test_cbgabi_is_one_and_random_zero(tmp_path):
    tasks = ["taskalloc/Small-v0", "taskalloc/Default-v0"]
    for policy, expected in (("cbgabi", 1.0), ("random", 0.0)):
        summary, _ = benchmark.run([policy], tasks, episodes=4)
        for task_id in tasks:
            assert summary["tasks"][task_id]["normalised"] == pytest.approx(expected, abs=1e-12)
            if policy == "random":          # paired with itself on every seed: no spread at all
                assert summary["tasks"][task_id]["ci95"] == [0.0, 0.0]


@pytest.mark.parametrize("task_id,policy", [
    ("taskalloc/Small-v0", "random"), ("taskalloc/Small-v0", "cbgabi"), ("taskalloc/Lossy-v0", "cbgabi"),
    ("taskalloc/Range-v0", "random"), pytest.param("taskalloc/Async-v0", "acbba", marks=pytest.mark.slow)])
def test_summary_scores_equal_plain_pettingzoo_episodes(task_id, policy):
    summary, rows = benchmark.run([policy], [task_id], episodes=3)
    entry = summary["tasks"][task_id]
    plain = []
    for seed in entry["seeds"]:
        agent = policy_for(policy)
        env = pettingzoo.make("parallel", task_id, **agent.env_overrides)
        observations, infos = env.reset(seed=seed)
        agent.start(env, seed)
        total = 0.0
        while env.agents:
            observations, rewards, _, _, infos = env.step(agent.act(observations, infos))
            total += next(iter(rewards.values()))
        plain.append(total * env.unwrapped.reward_scale)
    assert [r["score"] for r in rows] == pytest.approx(plain, abs=1e-6)
    assert entry["score"] == pytest.approx(np.mean(plain), abs=1e-6)
    assert entry["seeds"] == list(suite.task(task_id).test_seeds[:3])


def test_cli_writes_the_files_with_a_policy_by_import_path(tmp_path, user_module):
    out = tmp_path / "out"
    assert cli(["benchmark", "--policy", f"{user_module}:FirstBid", "--out", str(out), "--tasks", "Small",
                "Ladder6x12", "--episodes", "3"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["suite"] == "v0" and summary["policy"] == f"{user_module}:FirstBid"
    for task_id in ("taskalloc/Small-v0", "taskalloc/Ladder6x12-v0"):
        t = summary["tasks"][task_id]
        assert t["episodes"] == 3 and len(t["seeds"]) == 3 and t["ci95"][0] <= t["normalised"] <= t["ci95"][1]
        assert t["invalid_actions"] == 0
    assert summary["aggregate"]["iqm_ci95"][0] <= summary["aggregate"]["iqm_ci95"][1]
    rows = (out / "episodes.csv").read_text().splitlines()
    assert len(rows) == 1 + 6
    marl = json.loads((out / "marl_eval.json").read_text())
    run = marl["taskalloc"]["Small-v0"][summary["policy"]]["run_0"]
    assert len(run["absolute_metrics"]["return"]) == 3 and "step_0" in run
    assert "| taskalloc/Small-v0 |" in (out / "summary.md").read_text()
    # an existing --out is refused without --overwrite, accepted with it
    assert cli(["benchmark", "--policy", f"{user_module}:passes", "--out", str(out), "--tasks", "Small",
                "--episodes", "2"]) == 2
    assert cli(["benchmark", "--policy", f"{user_module}:passes", "--out", str(out), "--tasks", "Small",
                "--episodes", "2", "--overwrite"]) == 0
    assert json.loads((out / "summary.json").read_text())["tasks"]["taskalloc/Small-v0"]["episodes"] == 2


def test_invalid_actions_counted_under_noop_and_named_under_raise(tmp_path, user_module, capsys):
    out = tmp_path / "noop"
    assert cli(["benchmark", "--policy", f"{user_module}:out_of_mask", "--out", str(out), "--tasks", "Small",
                "--episodes", "2"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["tasks"]["taskalloc/Small-v0"]["invalid_actions"] >= 2 * 4      # every agent, every episode
    capsys.readouterr()
    assert cli(["benchmark", "--policy", f"{user_module}:out_of_mask", "--out", str(tmp_path / "raise"),
                "--tasks", "Small", "--episodes", "2", "--invalid-action", "raise"]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert "taskalloc/Small-v0, seed 50000" in err and "action 20 of uav_0" in err     # Discrete(1 + 2 · 8) + 3


@pytest.mark.parametrize("path", ["no_such_module_xyz:Policy", "suite_user_policy:Missing",
                                  "suite_user_policy:NOT_A_POLICY", "not a path", "learned:no_such_checkpoint"])
def test_bad_policy_is_one_line_and_exit_2(tmp_path, user_module, capsys, path):
    assert cli(["benchmark", "--policy", path, "--out", str(tmp_path / "o"), "--tasks", "Small"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("error:")
    assert not (tmp_path / "o").exists()


def test_a_task_the_policy_refuses_is_reported_not_applicable(user_module):
    summary, rows = benchmark.run([f"{user_module}:FourAgentsOnly"], ["taskalloc/Small-v0", "taskalloc/Ladder6x12-v0"],
                                  episodes=2)
    assert summary["tasks"]["taskalloc/Ladder6x12-v0"] == {"seeds": [50000, 50001], "episodes": 0,
                                                           "not_applicable": "trained on 4 agents"}
    assert summary["aggregate"]["tasks"] == 1 and {r["task"] for r in rows} == {"taskalloc/Small-v0"}
    assert "not applicable: trained on 4 agents" in benchmark.markdown(summary)


def test_centralised_solvers_run_and_exact_only_where_it_is_the_best_known():
    summary, _ = benchmark.run(["sgama"], ["taskalloc/Small-v0"], episodes=2)
    assert summary["policy"] == "SGAMA" and summary["tasks"]["taskalloc/Small-v0"]["episodes"] == 2
    summary, rows = benchmark.run(["exact"], ["taskalloc/Small-v0", "taskalloc/Default-v0"], episodes=2)
    reference = load_reference("v0")["tasks"]["taskalloc/Small-v0"]
    assert [r["score"] for r in rows] == pytest.approx(reference["best_known"][:2])
    assert summary["tasks"]["taskalloc/Default-v0"]["not_applicable"].startswith("exact runs only on the tasks")


def test_missing_rliable_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "rliable", None)
    with pytest.raises(ConfigError, match=r"taskalloc\[benchmark\]"):
        benchmark_stats.aggregate(np.zeros((3, 2)))


def test_intervals_over_runs_and_the_aggregate_rows():
    reference = {"random": 0.0, "random_per_seed": [0.0, 0.0, 0.0], "normaliser_score": 10.0,
                 "best_known_score": 20.0}
    one = benchmark_stats.task_figures([[5.0, 15.0, 10.0]], reference)
    assert one["normalised"] == pytest.approx(1.0) and one["best_known_share"] == pytest.approx(0.5)
    assert one["ci95"][0] < 1.0 < one["ci95"][1] and one["ci95_runs"] is None
    reference = {**reference, "random_per_seed": [0.0, 0.0]}
    runs = benchmark_stats.task_figures([[10.0, 10.0], [20.0, 20.0]], reference)
    assert runs["per_run_normalised"] == [1.0, 2.0] and runs["ci95"] == runs["ci95_runs"]
    matrix = benchmark_stats.aggregate_matrix({"a": np.ones((1, 5)), "b": np.zeros((1, 3))})
    assert matrix.shape == (3, 2)
    matrix = benchmark_stats.aggregate_matrix({"a": np.ones((2, 5)), "b": np.zeros((2, 3))})
    assert matrix.shape == (2, 2)


@pytest.mark.slow
def test_whole_suite_with_an_import_path_policy_and_the_baselines(tmp_path, user_module):
    assert cli(["benchmark", "--policy", f"{user_module}:FirstBid", "--out", str(tmp_path / "user"),
                "--episodes", "2"]) == 0
    assert set(json.loads((tmp_path / "user" / "summary.json").read_text())["tasks"]) == set(suite.TASKS)
    summary, _ = benchmark.run(["random"], list(suite.TASKS), episodes=3)
    assert all(t["normalised"] == pytest.approx(0.0, abs=1e-12) for t in summary["tasks"].values())
    for normaliser in {t.normaliser for t in suite.TASKS.values()}:
        ids = [i for i, t in suite.TASKS.items() if t.normaliser == normaliser]
        summary, _ = benchmark.run([normaliser], ids, episodes=3)
        assert all(t["normalised"] == pytest.approx(1.0, abs=1e-12) for t in summary["tasks"].values())


def test_docs_hold_the_cards_and_the_leaderboard_command():
    from pathlib import Path
    text = (Path(__file__).resolve().parents[1] / "docs" / "benchmark.md").read_text(encoding="utf-8")
    assert suite.cards() in text
    assert "taskalloc benchmark --leaderboard" in text


def test_aggregate_is_the_interquartile_mean_with_bootstrap_intervals():
    from scipy import stats
    matrix = np.array([[0.0, 1.0], [1.0, 1.0], [2.0, 1.0], [100.0, 1.0]])
    result = benchmark_stats.aggregate(matrix, reps=200)
    assert result["iqm"] == pytest.approx(stats.trim_mean(matrix.ravel(), 0.25))
    assert result["mean"] == pytest.approx(matrix.mean())
    assert result["iqm_ci95"][0] <= result["iqm_ci95"][1] < result["mean_ci95"][1]     # the outlier widens the mean's
    np.random.seed(5)  # noqa: NPY002  (the intervals do not depend on numpy's global state, which is given back)
    state = np.random.get_state()[1].copy()  # noqa: NPY002
    assert benchmark_stats.aggregate(matrix, reps=200) == result
    assert (np.random.get_state()[1] == state).all()  # noqa: NPY002


def test_several_runs_give_intervals_over_runs():
    summary, rows = benchmark.run(["cbgabi", "random"], ["taskalloc/Small-v0"], episodes=3, label="two runs")
    t = summary["tasks"]["taskalloc/Small-v0"]
    assert summary["policy"] == "two runs" and t["runs"] == 2 and t["episodes"] == 6
    assert t["per_run_normalised"] == pytest.approx([1.0, 0.0]) and t["normalised"] == pytest.approx(0.5)
    assert t["ci95"] == t["ci95_runs"] and t["ci95"][0] < 0.0 and t["ci95"][1] > 1.0     # t(1) is wide
    assert summary["aggregate"]["rows"] == 2 and {r["run"] for r in rows} == {0, 1}


def test_unknown_suite_and_bad_episodes_are_usage_errors(capsys):
    assert cli(["benchmark", "--suite", "v1", "--policy", "random", "--out", "x"]) == 2
    assert "unknown suite" in capsys.readouterr().err
    assert cli(["benchmark", "--policy", "random", "--out", "x", "--episodes", "0"]) == 2
    assert "--episodes" in capsys.readouterr().err


def test_learned_runs_carry_their_training_cost_into_the_leaderboard(tmp_path):
    from taskalloc.evaluation.training_cost import training_cost
    assert training_cost("cbgabi") is None
    cost = training_cost("learned:mappo_small_pooling_1m")        # MAPPO's summary.yaml keeps ``steps``
    assert cost["agent_steps"] == 1_003_520 and cost["wall_seconds"] == pytest.approx(463.1)
    assert training_cost("learned:train_small")["agent_steps"] == 1_003_520      # SB3's keeps ``ppo.steps``
    runs = ["learned:mappo_small_pooling_1m", "learned:mappo_small_pooling_1m"]
    summary, rows = benchmark.run(runs, ["taskalloc/Small-v0"], episodes=2, label="two runs")
    assert summary["training"] == [cost, cost]
    benchmark.write(tmp_path / "learned", summary, rows)
    summary, rows = benchmark.run(["cbgabi"], ["taskalloc/Small-v0"], episodes=2)
    assert "training" not in summary
    benchmark.write(tmp_path / "cbgabi", summary, rows)
    text = benchmark.leaderboard([tmp_path / "learned", tmp_path / "cbgabi"])
    row = next(line for line in text.splitlines() if line.startswith("| two runs | 2 |"))
    assert "1,003,520" in row and "7.6 (7.7)" in row            # CPU minutes (wall minutes)
    assert text.count("| CBGABI |") == 2                    # in the two score tables, not in the training one


LEADERBOARD = Path(__file__).resolve().parents[1] / "results" / "benchmark" / "v0"


def _learned_rows() -> list[tuple[str, int, str]]:
    """(folder, run, policy) of every learned run in the committed leaderboard."""
    rows = []
    for path in sorted(LEADERBOARD.glob("*/summary.json")):
        runs = json.loads(path.read_text(encoding="utf-8"))["runs"]
        rows += [(path.parent.name, k, p) for k, p in enumerate(runs) if p.startswith("learned:")]
    return rows


@pytest.mark.parametrize("folder,run,policy", _learned_rows())
def test_committed_leaderboard_models_load_by_name_and_reproduce_their_scores(folder, run, policy):
    """Each learned run of docs/benchmark.md loads by name and replays its first two recorded test episodes of the
    first task it was scored on (Small where it was) exactly."""
    from taskalloc.evaluation.suite_episodes import play
    with (LEADERBOARD / folder / "episodes.csv").open(encoding="utf-8") as handle:
        recorded = [r for r in csv.DictReader(handle) if int(r["run"]) == run]
    assert recorded, f"{folder}: no episodes for run {run}"
    tasks = [r["task"] for r in recorded]
    first = "taskalloc/Small-v0" if "taskalloc/Small-v0" in tasks else tasks[0]
    for row in [r for r in recorded if r["task"] == first][:2]:
        replay = play((policy, row["task"], int(row["seed"]), "noop"))
        assert replay["score"] == float(row["score"]) and replay["instance"] == row["instance"]


def test_versus_compares_each_run_with_the_baseline_on_the_same_seeds(tmp_path, capsys):
    """``--versus``: per run and task the share of the baseline's mean score, the paired p and the wins, from the
    committed episodes; the baseline against itself is 100 % with p = 1; a baseline of several runs, a folder
    without episodes and a seed that is another instance are refused in one line."""
    from taskalloc.evaluation.versus import versus_table
    base, mappo = LEADERBOARD / "cbgabi", LEADERBOARD / "learned_mappo_small_pooling_432k"
    table = versus_table(base, [base, mappo]).splitlines()
    assert table[0] == "| policy | run | task | episodes | % of CBGABI | paired p | wins |"
    assert "| CBGABI | 0 | Small | 100 | 100.00 | 1.00 | 0/100 |" in table
    assert "| MAPPO, pooling actor, 432 k | 0 | Small | 100 | 102.01 | <0.001 | 53/100 |" in table
    assert sum(line.startswith("| MAPPO") for line in table) == 3
    assert cli(["benchmark", "--versus", str(base), str(mappo)]) == 0
    assert "| MAPPO, pooling actor, 432 k | 2 | Small | 100 | 101.71 | 0.003 | 50/100 |" in capsys.readouterr().out
    with pytest.raises(ConfigError, match=r"must hold one run, it holds 3"):
        versus_table(mappo, [base])
    with pytest.raises(ConfigError, match=r"holds no episodes\.csv"):
        versus_table(base, [tmp_path])
    rows = (mappo / "episodes.csv").read_text(encoding="utf-8").splitlines()
    first = rows[1].split(",")
    first[4] = "another-instance"
    (tmp_path / "episodes.csv").write_text("\n".join([rows[0], ",".join(first)]) + "\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"Small-v0 seed 50000 is another instance"):
        versus_table(base, [tmp_path])
    assert cli(["benchmark", "--versus", str(base)]) == 2
