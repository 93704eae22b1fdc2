"""How much of the local plan a learned round-0 planner has learned (``research.evaluation.plan_fit``)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from research.evaluation import plan_fit
from taskalloc_env.errors import run_cli

ROOT = Path(__file__).resolve().parents[2]
PLANNER = "learned:planner_default"     # the committed planner (a pooling actor: it plays at any size)


def rows(table: str) -> dict[str, list[str]]:
    """The table's cells by row label."""
    cells = [[c.strip() for c in line.strip("|").split("|")] for line in table.splitlines()[2:]]
    return {row[0]: row[1:] for row in cells}


def test_the_cross_entropy_is_that_of_the_clipped_estimates():
    assert plan_fit.cross_entropy(np.array([0.5, 0.5]), np.array([1.0, 0.0])) == pytest.approx(math.log(2))
    assert plan_fit.cross_entropy(np.array([0.0, 1.0]), np.array([1.0, 0.0])) == pytest.approx(
        -math.log(plan_fit.CLIP))
    assert plan_fit.cross_entropy(np.array([1.0]), np.array([1.0])) == pytest.approx(-math.log(1 - plan_fit.CLIP))


def test_alone_the_local_plan_is_the_real_path_and_the_base_rate_its_share(tmp_path):
    """With one agent every drawn team is the instance itself, so the local plan's shares are the real path: the
    lowest cross-entropy the clipping allows, every task at ≥ ½ on the path and every one on the path found. The
    base rate scores the share of allowed tasks on the path, as its cross-entropy says."""
    scenario = yaml.safe_load((ROOT / "configs" / "scenarios" / "train_small.yaml").read_text())
    scenario.update(n_agents=1, agents_per_task=1)
    path = tmp_path / "alone.yaml"
    path.write_text(yaml.safe_dump(scenario))
    states = plan_fit.first_states((str(path), "exact", 2, [PLANNER], [3, 4, 5]))
    assert states.allowed.shape == states.on_path.shape == (3, 8) and states.on_path.any()
    assert not (states.on_path & ~states.allowed).any()
    table = rows(plan_fit.table(states))
    assert list(table) == ["base rate", PLANNER, "local plan (2 draws)"]
    local = table["local plan (2 draws)"]
    assert float(local[0]) == pytest.approx(-math.log(1 - plan_fit.CLIP), abs=1e-4)
    assert local[1:] == [str(states.on_path.sum()), "1.000", "1.000"]
    share = states.on_path[states.allowed].mean()
    assert float(table["base rate"][0]) == pytest.approx(
        -(share * math.log(share) + (1 - share) * math.log(1 - share)), abs=1e-4)


@pytest.mark.slow
def test_the_command_line_scores_each_planner_and_the_local_plan(capsys):
    table = plan_fit.main(["--planner", PLANNER, "--samples", "2", "--episodes", "2", "--jobs", "2"])
    assert list(rows(table)) == ["base rate", PLANNER, "local plan (2 draws)"]
    assert "train_small, seeds 20000–20001: " in capsys.readouterr().out


@pytest.mark.parametrize("argv, words", [
    (["--planner", "cbgabi"], ("--planner cbgabi", "not a round-0 planner")),
    (["--planner", "learned:nosuch"], ("--planner learned:nosuch",)),
    (["--planner", PLANNER, "--samples", "0"], ("--samples", ">= 1")),
    (["--planner", PLANNER, "--jobs", "0"], ("--jobs", ">= 1")),
    (["--planner", PLANNER, "--scenario", "default"], ("--scenario default", "--reference lns")),
])
def test_bad_arguments_are_one_line_and_exit_2(argv, words, capsys):
    assert run_cli(lambda: plan_fit.main(argv)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ")
    assert all(w in err[0] for w in words), err[0]
