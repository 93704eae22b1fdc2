"""The guides in docs/guides/ run as written and print what they show.

Each guide's fenced blocks run in order in an empty folder (on ``sys.path``), one namespace per guide:

- ```` ```python ````: executed; when the next block is an output block (no info string), what it prints must be
  exactly that block, as for the README's Quick start;
- ```` ```python file=NAME ```` and ```` ```yaml file=NAME ````: written to the folder as NAME;
- ```` ```bash ````: each line is a ``taskalloc`` command, run as ``python -m taskalloc`` in the folder; it must exit 0
  and print every line of the output block after it (an excerpt). These run the baselines' comparison, so they are
  the slow half of the test;
- any other info string (``sh``) is shown, not run.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
GUIDES = sorted((ROOT / "docs" / "guides").glob("*.md"))
BLOCK = re.compile(r"^```([^\n`]*)\n(.*?)^```[ \t]*$", flags=re.S | re.M)


def blocks(text: str) -> list[tuple[str, str]]:
    """(info string, body) of every fenced block, in order."""
    return [(info.strip(), body) for info, body in BLOCK.findall(text)]


def run_guide(guide: Path, folder: Path, commands: bool) -> int:
    """Run ``guide``'s blocks in ``folder`` (its ``bash`` commands only if ``commands``); the number of blocks run."""
    parts = blocks(guide.read_text(encoding="utf-8"))
    namespace: dict = {"__name__": f"guide {guide.stem}"}
    ran = 0
    for k, (info, body) in enumerate(parts):
        shown = parts[k + 1][1] if k + 1 < len(parts) and parts[k + 1][0] == "" else None
        kind, _, option = info.partition(" ")
        if option.startswith("file=") and kind in {"python", "yaml"}:
            (folder / option.removeprefix("file=")).write_text(body, encoding="utf-8")
        elif info == "python":
            out = io.StringIO()
            with contextlib.redirect_stdout(out):
                exec(compile(body, f"{guide.name} block {k}", "exec"), namespace)
            if shown is not None:
                assert out.getvalue() == shown, f"{guide.name} block {k} printed:\n{out.getvalue()}"
        elif info == "bash" and commands:
            for line in filter(None, (raw.strip() for raw in body.splitlines())):
                _run_command(line, folder, shown, guide.name)
        else:
            continue
        ran += 1
    return ran


def _run_command(line: str, folder: Path, shown: str | None, where: str) -> None:
    program, *args = shlex.split(line)
    assert program == "taskalloc", f"{where}: a bash block holds taskalloc commands only, got {line!r}"
    env = {**os.environ, "OMP_NUM_THREADS": "1",
           "PYTHONPATH": os.pathsep.join([str(ROOT), str(folder), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-m", "taskalloc", *args, "--no-progress"], cwd=folder, env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"{where}: {line} exited {done.returncode}: {done.stderr}"
    printed = {text.strip() for text in done.stdout.splitlines()}
    missing = [text for text in (shown or "").splitlines() if text.strip() and text.strip() not in printed]
    assert not missing, f"{where}: {line} did not print {missing}; it printed:\n{done.stdout}"


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """An empty working folder on ``sys.path``; modules the guide imports from it are forgotten afterwards."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    before = set(sys.modules)
    yield tmp_path
    for name in set(sys.modules) - before:
        if getattr(sys.modules[name], "__file__", None) and str(tmp_path) in sys.modules[name].__file__:
            del sys.modules[name]


def test_there_are_three_guides():
    assert {g.name for g in GUIDES} == {"your-own-policy.md", "your-own-scenario.md", "train-with-your-library.md"}


@pytest.mark.parametrize("guide", GUIDES, ids=lambda g: g.stem)
def test_the_guides_python_runs_and_prints_what_it_shows(guide, folder):
    assert run_guide(guide, folder, commands=False) >= 1


@pytest.mark.slow
@pytest.mark.parametrize("guide", GUIDES, ids=lambda g: g.stem)
def test_the_guides_commands_run_and_print_what_they_show(guide, folder):
    run_guide(guide, folder, commands=True)
