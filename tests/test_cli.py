"""The ``taskalloc`` command: every subcommand's help names it, boolean options are flags everywhere, a training
config given to the wrong trainer names the right one."""

from __future__ import annotations

import importlib
import importlib.util

import pytest
import yaml

from taskalloc.cli import COMMANDS, main, usage
from taskalloc_env import resources


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_subcommand_help_shows_its_own_usage(name, capsys):
    if name == "rllib" and importlib.util.find_spec("ray") is None:     # an extra that is not installed: one line
        assert main([name, "--help"]) == 1
        assert capsys.readouterr().err.strip() == ("taskalloc rllib: needs the Python package 'ray', which is not "
                                                   "installed (pip install 'taskalloc[ray]')")
        return
    with pytest.raises(SystemExit) as exit_:
        main([name, "--help"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.startswith(f"usage: taskalloc {name} ")


def test_the_top_level_help_lists_each_subcommand_in_one_line(capsys):
    assert main(["--help"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines == usage().splitlines()
    for name, (_, text) in COMMANDS.items():
        assert sum(line.split()[:1] == [name] and line.endswith(text) for line in lines) == 1, name


@pytest.mark.parametrize("module", ["train", "mappo"])
def test_boolean_training_options_are_flags_and_config_files_keep_booleans(module, tmp_path, capsys):
    load_config = importlib.import_module(f"taskalloc.training.{module}").load_config
    config = "train_small" if module == "train" else "mappo_small"
    out = ["--out-dir", str(tmp_path / "run")]
    assert load_config(["--config", config, *out, "--overwrite"]).overwrite is True
    assert load_config(["--config", config, *out, "--no-overwrite"]).overwrite is False
    with pytest.raises(SystemExit) as exit_:
        load_config(["--config", config, *out, "--overwrite", "true"])
    assert exit_.value.code == 2 and "unrecognized arguments: true" in capsys.readouterr().err
    own = tmp_path / "own.yaml"
    own.write_text(yaml.safe_dump({**yaml.safe_load(resources.named("training", config).read_text()),
                                   "overwrite": True}))
    assert load_config(["--config", str(own), *out]).overwrite is True
    assert load_config(["--config", str(own), *out, "--no-overwrite"]).overwrite is False


@pytest.mark.parametrize(("command", "config", "owner"), [("train", "mappo_small", "mappo"),
                                                          ("mappo", "train_small", "train")])
def test_a_config_for_the_other_trainer_names_it(command, config, owner, capsys):
    assert main([command, "--config", config]) == 2
    err = capsys.readouterr().err
    assert f"is for `taskalloc {owner}`" in err and f"run taskalloc {owner} --config {config}" in err
    assert "unknown fields" not in err and len(err.strip().splitlines()) == 1
