"""``python -m benchmarks.bench_env``: the quick path prints every section's table; bad flags are one line, exit 2."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchmarks.bench_env import fit_exponents, main, scaling_sizes
from taskalloc_env.errors import run_cli

REFERENCE = Path(__file__).resolve().parents[2] / "shared" / "anchors" / "CBBA-Python"


def test_quick_run_prints_every_section(capsys):
    args = ["--quick", "--max-size", "10x20", "--seconds", "0.2", "--strategy-seeds", "1"]
    if (REFERENCE / "lib" / "CBBA.py").is_file():
        args += ["--reference", str(REFERENCE)]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "agent-steps / CPU s" in out and "| random (masked) |" in out and "| CBGABI | 1 |" in out
    assert "| 10 × 20 |" in out and "| 10 × 10 |" in out and "exponent of N" in out
    assert "tracemalloc peak" in out and "ru_maxrss" in out and "| perfect |" in out
    if "--reference" in args:
        assert "| 5 × 10, windows |" in out and "CBBA-Python s" in out


def test_exponents_are_recovered_and_need_independent_sizes():
    sizes = [(10, 20), (20, 40), (50, 100), (100, 100), (100, 500)]
    a, b = fit_exponents(sizes, [n ** 2 * m for n, m in sizes])
    assert np.isclose(a, 2) and np.isclose(b, 1)
    assert fit_exponents([(10, 20), (20, 40)], [1.0, 2.0]) is None
    assert scaling_sizes(100, 500) == [(10, 20), (20, 40), (50, 100), (100, 100), (100, 200), (100, 500)]


@pytest.mark.parametrize("args", [["--max-size", "big"], ["--only", "nothing"], ["--solvers", "sgama"],
                                  ["--runs", "0"], ["--seeds", "x"], ["--repeats", "0"]])
def test_bad_flags_are_one_line_and_exit_2(args, capsys):
    assert run_cli(lambda: main(args)) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1


def test_episode_digests_repeat_and_see_a_changed_value(capsys, monkeypatch):
    """The same draw prints the same lines; an episode whose rewards change by one part in 10^12 prints another."""
    from benchmarks import episode_digests

    assert episode_digests.main(["--episodes", "6"]) == 0
    first = capsys.readouterr().out.splitlines()
    assert episode_digests.main(["--episodes", "6"]) == 0
    assert capsys.readouterr().out.splitlines() == first and len(first) == 6
    step = episode_digests.TaskAllocEnv.step

    def nudged(self, actions):
        out = step(self, actions)
        return out[0], {a: r * (1 + 1e-12) for a, r in out[1].items()}, *out[2:]
    monkeypatch.setattr(episode_digests.TaskAllocEnv, "step", nudged)
    assert episode_digests.main(["--episodes", "6"]) == 0
    changed = capsys.readouterr().out.splitlines()
    assert [line.split()[2] for line in changed] != [line.split()[2] for line in first]
    assert [line.split()[3] for line in changed] == [line.split()[3] for line in first]   # allocations unchanged


def test_episode_digests_refuse_bad_flags(capsys):
    from benchmarks import episode_digests

    assert run_cli(lambda: episode_digests.main(["--episodes", "0"])) == 2
    assert run_cli(lambda: episode_digests.main(["--policies", "nope"])) == 2
    assert capsys.readouterr().err.count("\n") == 2
