"""The process pool: results in item order, each as soon as it is ready, workers on one math thread each; the
compiled kernels cached once for every later process."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from taskalloc.evaluation.pool import THREADS_PER_WORKER, as_finished, parallel_map
from taskalloc_env import kernels
from taskalloc_env.kernels.cache import cache_dir

ROOT = Path(__file__).resolve().parents[1]


def slow_first(item: int) -> int:
    """Item 0 takes a second, the others no time (module level: the pool pickles it)."""
    if item == 0:
        time.sleep(1.0)
    return item * item


def torch_threads(_: int) -> int:
    """The threads torch would use in this process."""
    import torch

    return torch.get_num_threads()


@pytest.mark.slow
def test_results_come_back_as_they_finish_and_in_order_from_parallel_map():
    items = list(range(12))
    finished = list(as_finished(slow_first, items, jobs=2))
    assert sorted(finished) == [(i, i * i) for i in items]
    assert finished[0][0] != 0                      # the slow first item does not hold the others back
    assert list(parallel_map(slow_first, items, jobs=2)) == [i * i for i in items]
    assert list(parallel_map(slow_first, items, jobs=1)) == [i * i for i in items]


def test_workers_and_this_process_run_torch_on_one_thread_each(monkeypatch):
    torch = pytest.importorskip("torch")
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)           # torch's default: a thread per core
    assert set(parallel_map(torch_threads, list(range(4)), jobs=2)) == {THREADS_PER_WORKER}
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        assert set(parallel_map(torch_threads, list(range(2)), jobs=1)) == {THREADS_PER_WORKER}
        assert torch.get_num_threads() == 2                        # this process's setting is put back
    finally:
        torch.set_num_threads(before)


def test_the_kernel_cache_is_a_user_folder_not_the_package(monkeypatch, tmp_path):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert cache_dir() == tmp_path / "taskalloc" / "numba"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "mine"))
    assert cache_dir() == tmp_path / "mine"


EPISODE = """
from taskalloc.evaluation.episodes import Episode, run_episode
from taskalloc_env import kernels, resolve_config
cfg = resolve_config("default", n_agents=4, n_tasks=6)
for solver in ("random", "cbgabi", "sgama"):
    run_episode(Episode(solver, cfg, 0))
print(kernels.NOTICE.compiles)
"""


@pytest.mark.slow
@pytest.mark.skipif(not kernels.COMPILED, reason="numba is not installed")
def test_a_fresh_process_after_the_cache_exists_compiles_nothing(tmp_path):
    env = {key: value for key, value in os.environ.items() if key != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path)                           # the cache goes to <it>/taskalloc/numba

    def run() -> tuple[int, str]:
        done = subprocess.run([sys.executable, "-c", EPISODE], cwd=ROOT, env=env, capture_output=True, text=True,
                              check=True)
        return int(done.stdout.split()[-1]), done.stderr

    compiles, err = run()
    assert compiles > 0 and err.count("taskalloc: compiling the numba kernels") == 1    # announced once
    assert any((tmp_path / "taskalloc" / "numba").rglob("*.nbi"))                     # written to the cache
    compiles, err = run()
    assert compiles == 0 and "compiling" not in err


def test_kernel_cache_folder_follows_every_kernel_source(tmp_path, monkeypatch):
    """A kernel embeds the kernels it calls, so the cache folder changes when any kernel file does."""
    from taskalloc_env.kernels.cache import kernel_cache_dir, sources_digest
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "mine"))
    assert kernel_cache_dir() == tmp_path / "mine" / f"src-{sources_digest()}"
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "b.py").write_text("y = 1\n")
    before = sources_digest(tmp_path)
    (tmp_path / "b.py").write_text("y = 2\n")
    assert sources_digest(tmp_path) != before
