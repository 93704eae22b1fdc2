"""The pop-up replan study (``research.evaluation.popup_replan``) and the late-joiner study
(``research.evaluation.late_join``): their measures on hand-made histories, the pairing they rely on, their command
lines."""

from __future__ import annotations

import numpy as np
import pytest

from research.evaluation import late_join, popup_replan
from taskalloc.policies import make_policy, rollout
from taskalloc_env import TaskAllocEnv
from taskalloc_env.cbba_table import NONE
from taskalloc_env.errors import run_cli
from taskalloc_env.suite import task


def test_assignment_is_the_first_tick_the_final_holder_holds_it_and_settled_the_tick_it_holds_it_for_good():
    """Pop-up 0 (released at 10) held by agent 1 at ticks 12, 13, dropped at 14, held again from 15; pop-up 1
    (released at 11) held by agent 0 from 13 on, briefly by agent 1 at 12; pop-up 2 is never held."""
    ticks = np.arange(11, 18)
    held = np.zeros((len(ticks), 2, 3), dtype=bool)
    held[[1, 2, 4, 5, 6], 1, 0] = True          # ticks 12, 13, 15, 16, 17
    held[2:, 0, 1] = True                        # ticks 13 … 17
    held[1, 1, 1] = True                         # tick 12
    final, release = np.array([1, 0, NONE]), np.array([10, 11, 11])
    np.testing.assert_array_equal(popup_replan.first_held(held, final, release, ticks), [2, 2, np.nan])
    np.testing.assert_array_equal(popup_replan.settled(held, final, release, ticks), [5, 2, np.nan])


def test_acbba_with_release_actions_plays_the_episode_it_plays_without_them():
    """The study runs every arm with ``release_actions``; ACBBA takes none, so its figures are ACBBA's own."""
    row = popup_replan.run_seed(("ACBBA", 1, ()))
    plain = rollout(TaskAllocEnv(task(popup_replan.SUITE_TASK).config()), make_policy("acbba"), seed=1)
    assert (row["score"], row["broadcasts"], row["ticks"]) == (plain.score, plain.counters.broadcasts,
                                                               plain.counters.rounds)
    assert row["replans"] == row["dropped"] == 0 and row["sound"] and row["assigned"] == 25


def test_the_replan_arms_record_their_replans_and_where_the_dropped_tasks_end():
    row = popup_replan.run_seed(("replan, suffix", 1, (("max_bundle", 3),)))
    assert row["sound"] and row["replans"] > 0 and row["replanned_popups"] <= 25
    assert 0 <= row["won"] <= row["replans"] and 0 <= row["ahead"] <= row["replans"]
    assert row["kept"] + row["taken"] <= row["dropped"]
    assert np.all(row["settle"][~np.isnan(row["settle"])] >= row["assign"][~np.isnan(row["settle"])])


def test_the_replan_command_prints_both_tables_and_refuses_a_bad_field(capsys):
    assert run_cli(lambda: popup_replan.main(["--episodes", "2", "--jobs", "1"])) == 0
    out = capsys.readouterr().out
    assert "| replan, suffix |" in out and "| ACBBA | 2 | 2 |" in out and "replans per episode" in out
    assert run_cli(lambda: popup_replan.main(["--episodes", "2", "--set", "max_bundl=3"])) == 2
    assert "max_bundle" in capsys.readouterr().err


def test_a_late_joiner_run_pairs_with_the_same_instance_and_reports_what_the_joiner_holds():
    rows = late_join.run_seed(("train_small", "cbga", 2, (3,)))
    start, joined = rows
    assert (start["join"], joined["join"]) == (late_join.PRESENT, 3) and start["agent"] == joined["agent"] == 2
    assert joined["rounds"] > 3 and start["converged"] and joined["converged"]
    assert 0 <= joined["valid_held"] <= joined["held"] == len(joined["path"])


def test_the_late_join_command_prints_a_row_per_join_round_and_refuses_round_zero(capsys):
    assert late_join.main(["--episodes", "2", "--jobs", "1", "--scenarios", "train_small", "--rounds", "2"]) == 0
    out = capsys.readouterr().out
    assert out.count("| train_small |") == 4 and "| round 2 |" in out
    with pytest.raises(SystemExit):
        late_join.main(["--episodes", "2", "--rounds", "0"])
