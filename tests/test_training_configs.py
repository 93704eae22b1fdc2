"""Every committed training config (``configs/training/*.yaml``) loads and passes its tool's checks."""

from __future__ import annotations

from pathlib import Path

import pytest

from taskalloc_env import resources

CONFIGS = sorted(Path(resources.folder("training")).glob("*.yaml"))


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_every_committed_training_config_loads_and_passes_its_checks(path, tmp_path):
    argv = ["--config", path.stem, "--out-dir", str(tmp_path / "run")]
    if path.stem.startswith("mappo_"):
        from taskalloc.training import mappo

        cfg = mappo.load_config(argv)
    else:
        from taskalloc.training import train

        cfg = train.load_config(argv)
    assert cfg.name == path.stem
    assert not (tmp_path / "run").exists()      # loading a config writes nothing


def test_the_configs_are_found():
    names = {p.stem for p in CONFIGS}
    assert {"mappo_small_pooling", "mappo_delay_pooling", "train_small"} <= names
    assert not any(n.startswith(("planner_", "distil_", "mappo_after_planner", "mappo_round_zero")) for n in names), \
        "research configs live in research/configs"


@pytest.mark.parametrize(("given", "kept"), [("raw", "raw"), ("total_reward", "total_reward"), ("1e2", 100.0),
                                             ("7", 7.0)])
def test_the_sb3_reward_scale_takes_the_envs_names_and_numbers(given, kept, tmp_path):
    from taskalloc.training import train

    cfg = train.load_config(["--reward-scale", given, "--out-dir", str(tmp_path / "run")])
    assert cfg.reward_scale == kept and cfg.env_kwargs()["reward_scale"] == kept


@pytest.mark.parametrize("given", ["raww", "0", "-1", "inf"])
def test_a_bad_sb3_reward_scale_is_one_line_naming_the_field(given, tmp_path):
    from taskalloc.training import train
    from taskalloc_env.errors import ConfigError

    with pytest.raises(ConfigError) as info:
        train.load_config(["--reward-scale", given, "--out-dir", str(tmp_path / "run")])
    text = str(info.value)
    assert "\n" not in text and "'reward_scale'" in text and "'total_reward', 'raw'" in text, text
