"""``python -m benchmarks.bench_vector``: a short run prints both tables; a bad flag exits 2."""

from __future__ import annotations

import pytest

from benchmarks.bench_vector import main


@pytest.mark.slow
def test_short_run_prints_both_tables(capsys):
    main(["--sizes", "1", "4", "--seconds", "0.2", "--mappo-copies", "2", "--mappo-iterations", "1"])
    out = capsys.readouterr().out
    assert "| default | single env (dict API) | 1 |" in out and "| train_small | vector_env (arrays) | 4 |" in out
    assert "| train_small | vector_env (instances) | 4 |" in out
    assert "VMAS simple_spread" in out and "| vector_env | 2 |" in out and "share of time collecting" in out


@pytest.mark.slow
def test_phases_add_up_to_the_step(capsys):
    main(["--phases", "4", "--seconds", "0.2"])
    out = capsys.readouterr().out
    assert "| default | 4 |" in out and "| train_small | 4 |" in out and "| default+loss | 4 |" in out
    assert "end_rounds ms" in out and "resets ms" in out


def test_bad_flag_exits_2():
    with pytest.raises(SystemExit) as exc:
        main(["--sizes", "many"])
    assert exc.value.code == 2
