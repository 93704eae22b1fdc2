"""A learned round-0 planner's play rule, threshold by threshold, replanning and planning once
(``research.evaluation.planner_play``)."""

from __future__ import annotations

import numpy as np
import pytest

from research.evaluation import planner_play
from taskalloc.evaluation.episodes import evaluate
from taskalloc.policies import make_policy
from taskalloc_env.config import resolve_config
from taskalloc_env.errors import run_cli

PLANNER = "learned:planner_default"     # the committed planner (a pooling actor: it plays at any size)
SEEDS = [20_000, 20_001, 20_002]


def rows(table: str) -> list[list[str]]:
    return [[c.strip() for c in line.strip("|").split("|")] for line in table.splitlines()[4:]]


def mean_score(name: str) -> float:
    policy = make_policy(name)
    return float(np.mean([a.score for a in evaluate(policy, {"scenario": resolve_config("train_small")}, SEEDS)]))


def test_the_rows_are_the_follower_alone_then_both_rules_at_each_threshold_and_the_checkpoints_rule_reproduces():
    """The follower's row and the replanning row at the checkpoint's own threshold are the scores of the two
    policies as ``make_policy`` loads them; planning once at the same threshold is another policy."""
    table = planner_play.main(["--planner", PLANNER, "--thresholds", "0.5", "0.7", "--episodes", "3"])
    got = rows(table)
    assert [r[:2] for r in got] == [["learned:mappo_small_pooling_1m alone", "–"], ["replanning", "0.5"],
                                    ["planned once", "0.5"], ["replanning", "0.7"], ["planned once", "0.7"]]
    assert float(got[0][2]) == pytest.approx(mean_score("learned:mappo_small_pooling_1m"), abs=0.05)
    assert float(got[1][2]) == pytest.approx(mean_score(PLANNER), abs=0.05)
    assert got[0][3] == "100.0 %"


@pytest.mark.parametrize("argv, words", [
    (["--planner", "cbgabi"], ["--planner cbgabi", "not a round-0 planner"]),
    (["--planner", PLANNER, "--thresholds", "1.5"], ["--thresholds", "[1.5]", "(0, 1)"]),
    (["--planner", PLANNER, "--episodes", "1"], ["--episodes", "got 1", ">= 2"]),
])
def test_bad_arguments_are_one_line_and_exit_2(argv, words, capsys):
    assert run_cli(lambda: planner_play.main(argv)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ")
    assert all(w in err[0] for w in words), err[0]
