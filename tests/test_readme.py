"""The README's quick start runs and prints exactly what the README shows under it."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_the_quick_start_prints_what_the_readme_shows():
    section = README.read_text(encoding="utf-8").split("## Quick start", 1)[1].split("\n## ", 1)[0]
    code, shown = re.findall(r"```(?:python)?\n(.*?)```", section, flags=re.S)[:2]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "README quick start", "exec"), {})
    assert out.getvalue() == shown


def test_the_readme_says_what_rollout_does_with_a_policys_env_overrides():
    """``rollout`` checks the options (a runner applies them): the README says so, and rollout refuses an environment
    built without them."""
    import pytest

    from taskalloc.policies import make_policy, rollout
    from taskalloc_env import TaskAllocEnv

    text = " ".join(README.read_text(encoding="utf-8").split())
    assert re.search(r"`rollout` checks (it|them)", text)
    assert not re.search(r"apply (it|them)[^.]*\(`rollout`", text) and "`rollout`, `compare`" not in text
    with pytest.raises(ValueError, match="needs an environment with"):
        rollout(TaskAllocEnv("default"), make_policy("cbgabi"), seed=0)
