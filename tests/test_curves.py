"""Learning curves with intervals across seeds (``taskalloc curves``, ``taskalloc.evaluation.curves``)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from taskalloc.evaluation.curves import mean_and_band, read_eval
from taskalloc.training import curves
from taskalloc_env.errors import ConfigError, run_cli

MAPPO_HEADER = "steps,wall_time,entry,score,baseline_score,ratio,valid_tasks,rounds,messages\n"


def mappo_eval(path, ratios):
    rows = "".join(f"{k * 100},{k},{entry},{r * 10},10,{r},1,1,1\n" for k, r in enumerate(ratios)
                   for entry in ("default", "lossy"))
    path.write_text(MAPPO_HEADER + rows)
    return path


def test_read_eval_takes_mappo_ratios_per_entry_and_sb3_score_over_baseline(tmp_path):
    run = read_eval(mappo_eval(tmp_path / "m.csv", [0.9, 1.1]))
    assert run == {"default": [(0, 0.9), (100, 1.1)], "lossy": [(0, 0.9), (100, 1.1)]}
    sb3 = tmp_path / "s.csv"
    sb3.write_text("timesteps,score,baseline_score\n0,50,100\n2048,120,100\n")
    assert read_eval(sb3) == {"train_small": [(0, 0.5), (2048, 1.2)]}
    (tmp_path / "bad.csv").write_text("a,b\n1,2\n")
    with pytest.raises(ConfigError, match=r"is not an eval\.csv of taskalloc mappo or taskalloc train"):
        read_eval(tmp_path / "bad.csv")


def test_the_band_is_the_95_percent_t_interval_across_seeds_over_the_common_length():
    steps, mean, half = mean_and_band([[(0, 1.0), (10, 1.0), (20, 9.0)], [(0, 1.2), (10, 1.4)]])
    np.testing.assert_array_equal(steps, [0, 10])
    np.testing.assert_allclose(mean, [1.1, 1.2])
    np.testing.assert_allclose(half, stats.t.ppf(0.975, 1) * np.array([0.1, 0.2]))       # sd / √2 = 0.1, 0.2
    assert mean_and_band([[(0, 1.0)]])[2].tolist() == [0.0]


def test_cli_writes_the_png_and_refuses_to_replace_it_without_overwrite(tmp_path, capsys):
    a, b = mappo_eval(tmp_path / "a.csv", [0.9, 1.0, 1.1]), mappo_eval(tmp_path / "b.csv", [1.0, 1.0, 1.2])
    out = tmp_path / "curves.png"
    assert run_cli(lambda: curves.main(["--out", str(out), f"release={a},{b}", f"one seed={a}"])) == 0
    written = out.read_bytes()
    assert written[:4] == b"\x89PNG"
    assert run_cli(lambda: curves.main(["--out", str(out), f"release={a}"])) == 2
    assert "exists; pass --overwrite" in capsys.readouterr().err and out.read_bytes() == written
    assert run_cli(lambda: curves.main(["--out", str(out), "--overwrite", f"release={a}"])) == 0
    assert run_cli(lambda: curves.main(["--out", str(tmp_path / "x.png"), "no-equals-sign"])) == 2
    assert "expected LABEL=EVAL_CSV" in capsys.readouterr().err
    assert run_cli(lambda: curves.main(["--out", str(tmp_path / "y.png"), f"m={tmp_path / 'missing.csv'}"])) == 2
    assert "cannot read" in capsys.readouterr().err and not (tmp_path / "y.png").exists()
