"""The built wheel works anywhere: a fresh virtual environment, a directory outside the checkout.

Builds the wheel, installs it with the ``learned`` extra into a new venv, and from a temporary directory: makes the
env with no arguments and with the named scenarios, runs CBGABI, loads ``learned:train_small``, and runs
``taskalloc compare --episodes 2``.

Torch is not installed a second time: the new venv sees the running environment's torch (pinned first by the README's
set-up) and what torch needs, through a directory of links on its path, and nothing else of it. A second CPU torch is
about 750 MB, and installing it filled the CI machine's disk (CI of 2026-12-02: "No space left on device"). Every
other requirement of the wheel is installed into the new venv from its metadata, so a missing one still fails here.
"""

from __future__ import annotations

import importlib.metadata
import os
import shutil
import subprocess
import sys
import venv
from pathlib import Path

import pytest
from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parent.parent
TORCH = os.environ.get("TORCH_VERSION", "2.13.0")

pytestmark = pytest.mark.slow

SCRIPT = """
import pettingzoo, taskalloc_env
from taskalloc.policies import make_policy, rollout
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


def link_installed(name: str, into: Path) -> None:
    """Symlink the installed distribution ``name`` and those it requires (their top-level files) into ``into``."""
    into.mkdir(exist_ok=True)
    todo, seen = [name], set()
    while todo:
        dist = importlib.metadata.distribution(todo.pop())
        key = dist.metadata["Name"].lower()
        if key in seen:
            continue
        seen.add(key)
        todo += [req.name for req in map(Requirement, dist.requires or [])
                 if req.marker is None or req.marker.evaluate({"extra": ""})]
        for top in {Path(str(file)).parts[0] for file in dist.files or []} - {"..", "__pycache__"}:
            source = Path(str(dist.locate_file(top)))
            if source.suffix != ".pth" and not (into / top).exists():
                (into / top).symlink_to(source)


@pytest.fixture
def env_dir(tmp_path):
    """A path for the new venv, removed afterwards (it holds about 600 MB; the rest of the run needs the disk)."""
    yield tmp_path / "venv"
    shutil.rmtree(tmp_path / "venv", ignore_errors=True)


def test_wheel_installs_and_runs_outside_the_checkout(tmp_path, env_dir):
    dist = tmp_path / "dist"
    run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(dist), str(ROOT)], cwd=tmp_path)
    wheel = next(dist.glob("taskalloc-*.whl"))
    venv.create(env_dir, with_pip=True)
    python = str(env_dir / "bin" / "python")
    shared = tmp_path / "shared"
    link_installed("torch", shared)
    site = run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd=tmp_path).strip()
    Path(site, "shared_torch.pth").write_text(f"{shared}\n")
    assert run([python, "-c", "import torch; print(torch.__version__)"], cwd=tmp_path).startswith(TORCH)
    run([python, "-m", "pip", "install", "-q", f"{wheel}[learned]"], cwd=tmp_path)
    outside = tmp_path / "elsewhere"
    (outside / "training").mkdir(parents=True)             # a user's own modules with our layers' folder names
    for mine in ("evaluation.py", "policies.py", "training/__init__.py"):
        (outside / mine).write_text(f"MINE = {mine!r}\n")
    assert "site-packages" in run([python, "-c", SCRIPT], cwd=outside)
    table = run([str(env_dir / "bin" / "taskalloc"), "compare", "--scenario", "train_small", "--episodes", "2",
                 "--no-progress"], cwd=outside)
    assert "CBGABI" in table and "learned (train_small)" in table
    theirs = run([python, "-c", "import evaluation, policies, training, taskalloc.policies as ours; "
                  "print(evaluation.MINE, policies.MINE, training.MINE, ours.__file__)"], cwd=outside)
    assert theirs.split()[:3] == ["evaluation.py", "policies.py", "training/__init__.py"], theirs
    assert "site-packages" in theirs.split()[3]
