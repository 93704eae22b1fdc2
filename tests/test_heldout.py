"""``taskalloc.evaluation.heldout``: the quick table's rows on the same held-out instances, the centralised ones ordered
SGAMA ≤ LNS ≤ the exact optimum, and its markdown measured against CBGABI and the optimum."""

from __future__ import annotations

import numpy as np
import pytest

from taskalloc.evaluation import heldout


@pytest.mark.slow
def test_the_quick_table_orders_the_centralised_rows_and_reads_them_against_cbgabi():
    seeds = [10000, 10001, 10002]
    rows = heldout.run_rows("train_small", seeds, learned=[])
    scores = {r["label"]: np.array(r["scores"]) for r in rows}
    assert list(scores) == ["random", "CBGA", "CBGABI", "SGAMA (centralised greedy)",
                            "LNS (centralised group search)", "exact optimum"]
    assert np.all(scores["SGAMA (centralised greedy)"] <= scores["LNS (centralised group search)"] + 1e-9)
    assert np.all(scores["LNS (centralised group search)"] <= scores["exact optimum"] + 1e-9)
    table = heldout.markdown(rows, seeds)
    line = next(x for x in table.splitlines() if x.startswith("| exact optimum"))
    share = 100 * scores["exact optimum"].mean() / scores["CBGABI"].mean()
    assert line.split(" | ")[2:4] == [f"{share:.1f} %", "100.0 %"]


def test_the_default_learned_rows_are_committed_models_and_a_missing_one_is_refused_before_any_episode(
        tmp_path, monkeypatch):
    """The default rows name committed models only; a checkpoint that cannot be loaded stops the run with an error
    naming it, before any row is played, instead of being left out of the table."""
    from taskalloc.evaluation import compare
    from taskalloc.policies.checkpoint import CheckpointError
    from taskalloc_env import resources

    committed = set(resources.names("models", suffix=""))
    assert {path for _, path in heldout.DEFAULT_LEARNED} <= committed
    assert set(compare.DEFAULT_LEARNED) <= committed and len(compare.DEFAULT_LEARNED) <= 2
    assert compare.learned_checkpoints() == list(compare.DEFAULT_LEARNED)
    played = []
    monkeypatch.setattr(heldout, "run_episode", lambda episode: played.append(episode))
    with pytest.raises(CheckpointError, match="no_such_model"):
        heldout.run_rows("train_small", [10000], [("mine", "no_such_model")])
    with pytest.raises(CheckpointError, match="no checkpoint"):
        heldout.run_rows("train_small", [10000], [("mine", str(tmp_path / "gone" / "model.json"))])
    assert played == []
