"""``taskalloc compare``: every row, CBBA only where it applies, outputs, determinism, learned skips."""

from __future__ import annotations

import csv

import pytest

from taskalloc.cli import main

BASELINE_ROWS = ("random", "CBGA", "CBGA+TQ", "CBGA+TB", "CBGABI", "SGAMA", "LNS")


def _table_rows(text: str) -> dict[str, list[str]]:
    lines = [line for line in text.splitlines() if line.startswith("| ") and not line.startswith("| policy")]
    return {cells[0]: cells[1:] for cells in ([c.strip() for c in line.strip("|").split("|")] for line in lines)}


@pytest.mark.slow
def test_compare_prints_every_baseline_on_the_default_scenario(capsys):
    assert main(["compare", "--scenario", "default", "--episodes", "2", "--no-learned"]) == 0
    out = capsys.readouterr().out
    rows = _table_rows(out)
    assert set(rows) == set(BASELINE_ROWS)                     # L_j = 4: no CBBA row
    assert "CBBA: not run" in out
    for name in ("SGAMA", "LNS"):                                   # centralised: no rounds, no messages
        assert rows[name][2] == "–" and rows[name][3] == "–"
    assert all("±" in rows[name][0] for name in BASELINE_ROWS)


def test_cbba_row_appears_when_every_task_needs_one_agent(capsys):
    main(["compare", "--episodes", "2", "--set", "agents_per_task=1", "--set", "n_agents=4", "--set", "n_tasks=8",
          "--no-learned"])
    rows = _table_rows(capsys.readouterr().out)
    assert set(rows) == {*BASELINE_ROWS, "CBBA", "CBAA", "PI"}


@pytest.mark.slow
def test_compare_is_deterministic_and_writes_table_and_plot(tmp_path, capsys):
    argv = ["compare", "--episodes", "3", "--set", "n_agents=5", "--set", "n_tasks=8", "--no-learned"]
    main([*argv, "--out", str(tmp_path)])
    first = capsys.readouterr().out
    main([*argv, "--jobs", "2"])
    assert capsys.readouterr().out.split("written:")[0] == first.split("written:")[0]
    for name in ("compare.md", "compare.csv", "episodes.csv", "compare.png"):
        assert (tmp_path / name).stat().st_size > 0
    with open(tmp_path / "compare.csv", newline="") as fh:
        records = list(csv.DictReader(fh))
    assert [r["policy"] for r in records] == list(BASELINE_ROWS)
    with open(tmp_path / "episodes.csv", newline="") as fh:
        episodes = list(csv.DictReader(fh))
    assert len(episodes) == 3 * len(BASELINE_ROWS)
    assert len({(r["seed"], r["instance"]) for r in episodes}) == 3   # paired: one instance per seed


@pytest.mark.parametrize("source", ["nonexistent", "runs/none/model.zip"])
def test_a_learned_policy_asked_for_that_cannot_load_is_a_usage_error(source, capsys):
    assert main(["compare", "--episodes", "2", "--no-progress", "--learned", source]) == 2
    captured = capsys.readouterr()
    assert f"--learned {source}: the checkpoint cannot be loaded" in captured.err
    assert "|" not in captured.out                                  # refused before any episode


def test_a_committed_model_that_does_not_fit_is_skipped_with_a_note(monkeypatch):
    from taskalloc.evaluation import compare

    monkeypatch.setattr(compare, "learned_checkpoints", lambda: ["nonexistent"])
    monkeypatch.setattr(compare, "BASELINES", ("cbga",))
    text = compare.compare("default", 2, {"n_agents": 4, "n_tasks": 6})
    assert "learned policy nonexistent: skipped, the checkpoint cannot be loaded" in text
    assert set(_table_rows(text)) == {"CBGA"}
