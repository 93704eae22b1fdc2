"""The built wheel works anywhere: a fresh virtual environment, a directory outside the checkout.

Builds the wheel, installs it (with the ``learned`` extra, torch pinned first as the README's set-up does) into a new
venv, and from a temporary directory: makes the env with no arguments and with the named scenarios, runs CBGABI,
loads ``learned:train_small``, and runs ``python -m policies compare --episodes 2``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
TORCH = os.environ.get("TORCH_VERSION", "2.13.0")

pytestmark = pytest.mark.slow

SCRIPT = """
import pettingzoo, taskalloc_env
from policies import make_policy, rollout
env = pettingzoo.make("parallel", "taskalloc/TaskAlloc-v0")
obs, infos = env.reset(seed=0)
assert len(env.agents) == 10 and obs["uav_0"]["observation"].dtype.name == "float32"
for name in ("default", "train_small"):
    cbgabi = make_policy("cbgabi")
    allocation = rollout(taskalloc_env.TaskAllocEnv(name, **cbgabi.env_overrides), cbgabi, seed=1)
    assert allocation.converged and allocation.score > 0, name
learned = make_policy("learned:train_small")
allocation = rollout(taskalloc_env.TaskAllocEnv("train_small", **learned.env_overrides), learned, seed=1)
assert allocation.score > 0
print("ok", taskalloc_env.__file__)
"""


def run(cmd: list[str], cwd: Path, timeout: int = 900) -> str:
    result = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout,
                            env={**os.environ, "PYTHONPATH": "", "OMP_NUM_THREADS": "1"})
    assert result.returncode == 0, f"{' '.join(cmd)} failed:\n{result.stdout[-2000:]}\n{result.stderr[-3000:]}"
    return result.stdout


def test_wheel_installs_and_runs_outside_the_checkout(tmp_path):
    dist = tmp_path / "dist"
    run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(dist), str(ROOT)], cwd=tmp_path)
    wheel = next(dist.glob("taskalloc-*.whl"))
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True)
    python = str(env_dir / "bin" / "python")
    index = os.environ.get("TORCH_INDEX_URL")          # as scripts/setup.sh: the CPU index where pip's own is CUDA
    run([python, "-m", "pip", "install", "-q", *(["--index-url", index] if index else []), f"torch=={TORCH}"],
        cwd=tmp_path)
    run([python, "-m", "pip", "install", "-q", f"{wheel}[learned]"], cwd=tmp_path)
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    assert "site-packages" in run([python, "-c", SCRIPT], cwd=outside)
    table = run([python, "-m", "policies", "compare", "--episodes", "2", "--no-progress"], cwd=outside)
    assert "CBGABI" in table and "learned (train_small)" in table
