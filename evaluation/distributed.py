"""Episodes as Ray tasks: the ``ray`` backend of ``run_episodes`` (``--backend ray`` in compare and experiments).

A sweep is cut into chunks of episodes; each chunk is one Ray task that runs
``taskalloc.evaluation.episodes.run_episode`` on its episodes, and the rows come back in the order of the episodes, so a
table is byte for byte the one the local backend writes for the same seeds (every episode is a pure function of its
solver, config and seed). Ray starts locally unless ``RAY_ADDRESS`` names a cluster (``ray start --head`` on one
machine, ``ray start
--address=<head>:6379`` on the others; taskalloc must be installed on every node: ``pip install taskalloc[ray]``).
A learned policy named by a path is read on the worker: it must exist there (committed models, named
``learned:<name>``, travel inside the package). Ray is imported only here, and only when this backend is used.
"""

from __future__ import annotations

import importlib.util
import os
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from taskalloc_env.errors import ConfigError

BACKENDS = ("local", "ray")
CHUNKS_PER_CPU = 4          # enough chunks to keep every CPU busy while the slowest ones finish


def require_ray() -> None:
    """Refuse the ray backend, before anything runs, when Ray is not installed."""
    if importlib.util.find_spec("ray") is None:
        raise ConfigError("the ray backend needs Ray, which is not installed: pip install 'taskalloc[ray]'")


def init_ray() -> Any:
    """Ray, started locally (``address="local"``) or joined to ``RAY_ADDRESS``; Ray's own default (None) joins the
    last cluster started on this machine, and hung when that one was gone."""
    require_ray()
    import ray

    if not ray.is_initialized():
        ray.init(address=os.environ.get("RAY_ADDRESS", "local"), include_dashboard=False, log_to_driver=False)
    return ray


def _run_chunk(fn: Callable[[Any], Any], items: Sequence[Any], cwd: str) -> list[Any]:
    """One Ray task: ``fn`` on every item, from the driver's working directory when this node has it (paths of
    learned checkpoints are relative to it)."""
    if os.path.isdir(cwd):
        os.chdir(cwd)
    return [fn(item) for item in items]


def ray_map(fn: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[Any]:
    """``map(fn, items)`` over the Ray cluster, in order."""
    ray = init_ray()
    cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
    size = max(1, -(-len(items) // (CHUNKS_PER_CPU * cpus)))
    task = ray.remote(num_cpus=1)(_run_chunk)
    refs = [task.remote(fn, items[i: i + size], os.getcwd()) for i in range(0, len(items), size)]
    for ref in refs:
        yield from ray.get(ref)
