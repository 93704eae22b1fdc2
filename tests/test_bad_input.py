"""Bad and hostile input: every case is refused with an error that names what is wrong.

Explicit scenarios, config fields, scenario names and files, resource estimates, crafted checkpoints and fault
options; then the command lines: one line on stderr, exit status 2, existing output left as it was.
"""

from __future__ import annotations

import base64
import json
import os
import pickle
import subprocess
import sys
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from taskalloc.cli import main as compare_main
from taskalloc.evaluation import experiments
from taskalloc.policies import make_policy
from taskalloc.policies.checkpoint import CheckpointError
from taskalloc.policies.learned import LearnedPolicy
from taskalloc_env import Agent, ConfigError, Scenario, Task, TaskAllocEnv, resolve_config
from taskalloc_env.errors import run_cli
from taskalloc_env.memory import check_memory

ROOT = Path(__file__).resolve().parent.parent
NAN, INF = float("nan"), float("inf")


def _scenario(speed: float = 1.0, reward: float = 100.0, agents: Any = 1) -> Scenario:
    return Scenario.from_entities([Agent((0.0, 0.0, 0.0), speed)],
                                  [Task((1.0, 0.0, 0.0), reward, 0.0, 50.0, 1.0, agents=agents)])


# -- explicit scenarios and configs --------------------------------------------------------------------------------
BAD_INPUT: dict[str, tuple[Callable[[], object], type[Exception], tuple[str, ...]]] = {
    "nan speed": (lambda: _scenario(speed=NAN), ValueError, ("agent_speed", "nan", "finite")),
    "inf speed": (lambda: _scenario(speed=INF), ValueError, ("agent_speed", "inf", "finite")),
    "nan reward": (lambda: _scenario(reward=NAN), ValueError, ("task_reward", "nan", "finite")),
    "inf reward": (lambda: _scenario(reward=-INF), ValueError, ("task_reward", "inf", "finite")),
    "task agents 1.5": (lambda: _scenario(agents=1.5), ValueError, ("task 0", "agents 1.5", "integer")),
    "task agents '2'": (lambda: _scenario(agents="2"), ValueError, ("task 0", "agents '2'", "integer")),
    "name escapes its folder": (lambda: resolve_config("../../../../etc/x"), ConfigError,
                                ("'../../../../etc/x'", "is not a bare name")),
    "n_agents 1.5": (lambda: resolve_config(n_agents=1.5), ConfigError, ("'n_agents'", "1.5", "integer")),
    "n_agents '2'": (lambda: resolve_config(n_agents="2"), ConfigError, ("'n_agents'", "'2'", "integer")),
    "override on a fixed scenario": (lambda: TaskAllocEnv(_scenario(), speed=1e9), ConfigError,
                                     ("['speed']", "cannot apply to a fixed Scenario")),
    "arena 1e308": (lambda: resolve_config(arena=1e308), ConfigError, ("'arena'", "1e+308")),
    "arena entries 1e308": (lambda: resolve_config(arena=[1e308] * 3), ConfigError, ("'arena'", "±1e+09")),
    "reward 1e308": (lambda: resolve_config(reward=1e308), ConfigError, ("'reward'", "±1e+09")),
    "start_time_range [0]": (lambda: resolve_config(start_time_range=[0]), ConfigError,
                             ("'start_time_range'", "two times")),
    "start_time_range ±1e308": (lambda: resolve_config(start_time_range=[-1e308, 1e308]), ConfigError,
                                ("'start_time_range'", "±1e+09")),
    "followup_window 'no'": (lambda: resolve_config(prerequisites={"chains": 1, "followup_window": "no"}),
                             ConfigError, ("'prerequisites.followup_window'", "'no'", "true | false")),
    "reward_scale '2'": (lambda: TaskAllocEnv(reward_scale="2"), ConfigError, ("reward_scale", "'2'", "number")),
    "scenario 123": (lambda: resolve_config(123), ConfigError, ("scenario", "123", "int", "scenario name")),
    "env scenario 123": (lambda: TaskAllocEnv(scenario=123), ConfigError, ("scenario", "123", "int")),
    "message_loss 1.5": (lambda: resolve_config(message_loss=1.5), ConfigError,
                         ("'message_loss'", "1.5", "probability in [0, 1]")),
    "burst_loss 2": (lambda: resolve_config(burst_loss=2.0), ConfigError, ("'burst_loss'", "probability")),
    "burst_enter -0.1": (lambda: resolve_config(burst_enter=-0.1), ConfigError, ("'burst_enter'", "probability")),
    "burst_leave 1.01": (lambda: resolve_config(burst_leave=1.01), ConfigError, ("'burst_leave'", "probability")),
    "max_delay -1": (lambda: resolve_config(max_delay=-1), ConfigError, ("'max_delay'", "-1", "integer >= 0")),
    "unknown loss_model": (lambda: resolve_config(loss_model="bursty"), ConfigError,
                           ("'loss_model'", "'bursty'", "independent", "gilbert_elliott")),
}


@pytest.mark.parametrize("case", list(BAD_INPUT))
def test_bad_input_is_refused_naming_the_field(case):
    make, error, words = BAD_INPUT[case]
    with pytest.raises(error) as info:
        make()
    for word in words:
        assert word in str(info.value), f"{case}: {word!r} not in {str(info.value)!r}"


# -- resource estimates ------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("n", "m", "bundle", "width", "asynchronous", "term"), [
    (10**9, 20, None, None, False, "local tables of N·M·L"),
    (10**6, 1, None, 1, False, "N·N arrays"),
    (10, 10**9, None, 4, False, "path gains of N·M·(P+1)"),
    (10**4, 10**5, 3, 8, False, "local tables of N·M·L"),
    (10, 10**6, 3, 4, False, "M·M arrays"),
    (2000, 1000, 3, 4, True, "per-entry times of N·N·M"),
])
def test_huge_sizes_are_refused_naming_the_dominant_term(n, m, bundle, width, asynchronous, term):
    with pytest.raises(ConfigError) as info:
        check_memory(n, m, bundle, 16.0, width, asynchronous)
    text = str(info.value)
    assert f"{n} agents × {m} tasks" in text and f"mostly {term}" in text, text
    assert "memory_limit_gb" in text


def test_the_sparse_tables_admit_what_dense_ones_could_not():
    """2000 agents × 1000 tasks at L_j ≤ 4: the synchronous tables fit in 16 GiB (N·M·L slots), the asynchronous
    protocol's per-entry times (N·N·M) do not."""
    check_memory(2000, 1000, 3, 16.0, 4, asynchronous=False)
    with pytest.raises(ConfigError):
        check_memory(2000, 1000, 3, 16.0, 4, asynchronous=True)


def test_a_million_agents_are_refused_before_allocating():
    """The memory estimate refuses a size at the count limit; a billion agents are past the limit itself."""
    with pytest.raises(ConfigError, match=r"1000000 agents × 20 tasks need about .* GiB"):
        TaskAllocEnv(n_agents=10**6)
    with pytest.raises(ConfigError, match=r"'n_agents': got 1000000000; allowed: an integer >= 1 and <= 1e\+06"):
        TaskAllocEnv(n_agents=10**9)


# -- scenario files ------------------------------------------------------------------------------------------------
YAML_FILES: dict[str, tuple[bytes | None, tuple[str, ...]]] = {
    "parse error": (b"n_agents: 4\nn_tasks: [1, 2\nspeed: 3\n", ("is not valid YAML", "line 3, column 6")),
    "non-UTF-8": (b"n_agents: 4\nname: \"\xff\xfe\"\n", ("is not UTF-8 text", "byte 19")),
    "folder": (None, ("is a folder, not a file",)),
    "deep nesting": (b"a: " + b"[" * 1000 + b"]" * 1000 + b"\n", ("nests too deeply",)),
    "unknown key": (b"n_agents: 4\nspeeed: 2\n", ("unknown config field 'speeed' (did you mean 'speed'?)",)),
    "not a mapping": (b"- 1\n- 2\n", ("must hold a mapping of config fields", "list")),
}


@pytest.mark.parametrize("case", list(YAML_FILES))
def test_bad_scenario_file_is_one_config_error_naming_the_file(case, tmp_path):
    content, words = YAML_FILES[case]
    path = tmp_path / "bad.yaml"
    if content is None:
        path.mkdir()
    else:
        path.write_bytes(content)
    for source in (path, str(path)):
        with pytest.raises(ConfigError) as info:
            resolve_config(source)
        text = str(info.value)
        assert f"scenario file {str(path)!r}" in text, text
        for word in words:
            assert word in text, f"{case}: {word!r} not in {text!r}"


# -- crafted checkpoints -------------------------------------------------------------------------------------------
class _WritesMarker:
    """Unpickling this calls ``Path.write_text`` on the marker: what a hostile checkpoint would do."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple:
        return Path.write_text, (self.marker, "pwned")


def crafted_zip(folder: Path) -> tuple[Path, Path]:
    """An SB3-style zip whose ``data`` holds a pickle that writes a marker file when loaded; (zip, marker)."""
    marker = folder / "marker.txt"
    payload = base64.b64encode(pickle.dumps(_WritesMarker(marker))).decode()
    data = {"policy_class": {":type:": "<class 'abc.ABCMeta'>", ":serialized:": payload},
            "policy_kwargs": {}}
    path = folder / "model.zip"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("data", json.dumps(data))
        archive.writestr("policy.pth", b"")
        archive.writestr("_stable_baselines3_version", "2.0.0")
    return path, marker


@pytest.mark.parametrize("entry", ["LearnedPolicy.load", "make_policy"])
def test_crafted_pickle_checkpoint_is_refused_and_runs_nothing(entry, tmp_path):
    path, marker = crafted_zip(tmp_path)
    with pytest.raises(CheckpointError) as info:
        LearnedPolicy.load(str(path)) if entry == "LearnedPolicy.load" else make_policy(f"learned:{path}")
    text = str(info.value)
    assert "stable-baselines3 zip" in text and "allow_pickle=True" in text
    assert "taskalloc checkpoint convert" in text
    assert "--allow-pickle" not in text                        # no command line has such a flag
    assert not marker.exists()


def test_the_crafted_checkpoint_would_run_code_if_allowed(tmp_path):
    """The fixture is hostile for real: SB3's loader, once allowed, writes the marker (so the test above can fail)."""
    pytest.importorskip("stable_baselines3")
    path, marker = crafted_zip(tmp_path)
    with pytest.warns(UserWarning, match="runs any code"), pytest.raises(EOFError):  # then: empty policy.pth
        LearnedPolicy.load(str(path), allow_pickle=True)
    assert marker.read_text() == "pwned"


# -- command lines -----------------------------------------------------------------------------------------------
def cli(*argv: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, *argv], cwd=cwd, env=env, capture_output=True, text=True, timeout=300)


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def in_process(main: Callable[[list[str]], object], argv: list[str], capsys: Any) -> subprocess.CompletedProcess:
    """``main(argv)`` the way ``python -m`` runs it (``run_cli``), with what it printed."""
    code = run_cli(lambda: main(argv))
    out, err = capsys.readouterr()
    return subprocess.CompletedProcess(argv, code, out, err)


def _one_error_line(result: subprocess.CompletedProcess, *words: str) -> str:
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    for word in words:
        assert word in lines[0], f"{word!r} not in {lines[0]!r}"
    return lines[0]


def test_compare_refuses_an_existing_output_folder(tmp_path):
    out = tmp_path / "compare"
    out.mkdir()
    (out / "compare.md").write_text("committed table\n")
    before = _snapshot(out)
    result = cli("-m", "taskalloc", "compare", "--episodes", "2", "--no-learned", "--out", str(out))
    _one_error_line(result, f"--out {out}", "not empty", "--overwrite")
    assert result.stdout == "" and _snapshot(out) == before


@pytest.mark.slow
def test_compare_overwrites_when_asked(tmp_path, capsys):
    out = tmp_path / "compare"
    out.mkdir()
    (out / "compare.md").write_text("committed table\n")
    argv = ["compare", "--episodes", "2", "--no-learned", "--no-progress", "--set", "n_agents=4", "--set",
            "n_tasks=6", "--jobs", "1", "--out", str(out), "--overwrite"]
    result = in_process(compare_main, argv, capsys)
    assert result.returncode == 0, result.stderr
    assert (out / "compare.md").read_text().startswith("# Policy comparison")


def test_compare_reports_a_refused_checkpoint_with_its_reason(tmp_path, capsys):
    path, marker = crafted_zip(tmp_path)
    assert compare_main(["compare", "--episodes", "2", "--set", "n_agents=4", "--set", "n_tasks=6", "--jobs", "1",
                 "--no-progress", "--learned", str(path)]) == 2
    note = capsys.readouterr().err.strip()
    assert note.startswith(f"error: --learned {path}: ") and "\n" not in note, note
    assert "cannot be loaded" in note and "stable-baselines3 zip" in note, note
    assert "does not fit this scenario" not in note
    assert not marker.exists()


EXPERIMENT = "name: tiny\nscenario: default\noverrides: {n_agents: 3, n_tasks: 3, agents_per_task: 1}\n" \
             "series: [cbga]\nepisodes: 2\n"
BAD_EXPERIMENTS = {
    "bad key": ("name: x\nsereis: [cbga]\n", ("unknown keys ['sereis']",)),
    "no sweep values": ("name: x\nseries: [cbga]\nsweep: {field: n_agents}\n", ("sweep values", "non-empty list")),
    "empty sweep values": ("name: x\nseries: [cbga]\nsweep: {field: n_agents, values: []}\n",
                           ("sweep values", "non-empty list", "[]")),
    "sweep not a mapping": ("name: x\nseries: [cbga]\nsweep: 5\n", ("sweep is", "got 5")),
    "series without solver": ("name: x\nseries: [{label: a}]\n", ("required key is missing", "'solver'")),
    "bad override": ("name: x\nseries: [cbga]\noverrides: {speeed: 1}\n",
                     ("unknown config field 'speeed' (did you mean 'speed'?)",)),
    "bad episodes": ("name: x\nseries: [cbga]\nepisodes: many\n", ("episodes", "'many'", "integer >= 1")),
}


@pytest.mark.parametrize("case", list(BAD_EXPERIMENTS))
def test_experiment_run_with_a_bad_file_is_one_line_and_exit_2(case, tmp_path, capsys):
    text, words = BAD_EXPERIMENTS[case]
    path = tmp_path / "exp.yaml"
    path.write_text(text)
    argv = ["run", str(path), "--out", str(tmp_path / "out"), "--no-docs"]
    _one_error_line(in_process(experiments.main, argv, capsys), str(path), *words)
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_experiment_run_refuses_existing_results_and_docs(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text(EXPERIMENT)
    out, docs = tmp_path / "out", tmp_path / "results.md"
    (out / "tiny").mkdir(parents=True)
    (out / "tiny" / "table.md").write_text("committed\n")
    docs.write_text("# Results\n\n<!-- results:tiny:start -->\nold\n<!-- results:tiny:end -->\n")
    before = _snapshot(tmp_path)
    base = ("-m", "taskalloc", "experiments", "run", str(path), "--jobs", "1", "--no-progress")
    _one_error_line(cli(*base, "--out", str(out), "--no-docs"), f"{out / 'tiny'}", "not empty", "--overwrite")
    _one_error_line(cli(*base, "--out", str(tmp_path / "new"), "--docs", str(docs)),
                    str(docs), "already holds the results of tiny", "--overwrite", "--no-docs")
    assert _snapshot(tmp_path) == before and not (tmp_path / "new").exists()


@pytest.mark.slow
def test_experiment_run_overwrites_when_asked(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text(EXPERIMENT)
    out = tmp_path / "out"
    (out / "tiny").mkdir(parents=True)
    (out / "tiny" / "table.md").write_text("committed\n")
    result = cli("-m", "taskalloc", "experiments", "run", str(path), "--jobs", "1", "--no-progress", "--out",
                 str(out), "--no-docs", "--overwrite")
    assert result.returncode == 0, result.stderr
    assert (out / "tiny" / "table.md").read_text() != "committed\n"


def test_main_script_regenerates_the_committed_table_with_overwrite():
    text = (ROOT / "scripts" / "main.sh").read_text()
    assert "--out results/compare --overwrite" in text


@pytest.mark.parametrize(("command", "written"), [
    (("-m", "taskalloc", "figures", "links"), "fig.png"),
    (("-m", "taskalloc", "acbba-experiments", "sweep", "--seeds", "1", "--jobs", "1"), "sweep.md"),
])
def test_figure_and_acbba_commands_refuse_to_replace_results(tmp_path, command, written):
    out = tmp_path / "out"
    out.mkdir()
    (out / written).write_text("committed\n")
    before = _snapshot(tmp_path)
    _one_error_line(cli(*command, "--out", str(out)), str(out), "--overwrite")
    assert _snapshot(tmp_path) == before
