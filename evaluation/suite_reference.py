"""The suite's normalisers, computed once per suite version and committed: ``configs/suites/v0/reference.json``.

For every task and test seed: the score of the uniform random masked policy (0 on the normalised scale), of the
task's normalising baseline (1: CBGABI, or the one the card names) and of the best-known solver (the exact optimum
where it enumerates, else the group search LNS, a lower bound of the optimum). ``taskalloc benchmark
--write-reference`` recomputes the file; the benchmark reads it instead of replaying the baselines, and
tests/test_benchmark.py checks that some entries reproduce.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from taskalloc.evaluation.episodes import fingerprint
from taskalloc.evaluation.suite_episodes import play_task, task_env
from taskalloc_env import TaskAllocConfig, resources
from taskalloc_env.errors import ConfigError
from taskalloc_env.suite import SUITE, TASKS

# the fields of the network's faults (taskalloc_env/options/network.py): the centralised solvers ignore them
FAULT_FIELDS = ("message_loss", "loss_model", "burst_enter", "burst_leave", "burst_loss", "burst_correlation",
                "fading_distance", "fading_exponent", "max_delay", "dropouts", "dropout_rounds", "dropout_schedule",
                "silence_timeout")


def reference_path(suite: str = SUITE) -> Path:
    """Where the checkout keeps the suite's reference (written by ``--write-reference``)."""
    return resources.CHECKOUT / "configs" / "suites" / suite / "reference.json"


def load_reference(suite: str = SUITE) -> dict[str, Any]:
    """The committed reference of ``suite`` (from the installed package or the checkout)."""
    node = resources.data_root() / "configs" / "suites" / suite / "reference.json"
    if not node.is_file():
        raise ConfigError(f"suite {suite!r} has no reference file ({node}); run taskalloc benchmark --write-reference")
    return json.loads(node.read_text(encoding="utf-8"))


def static_problem(task_id: str, seed: int) -> tuple[str, TaskAllocConfig]:
    """Instance ``seed`` of the task without its faults: the fingerprint of the drawn instance and the config with
    every fault field at its default. The centralised solvers see only this (faults act on the protocol)."""
    env = task_env("random", task_id)
    env.reset(seed=seed)
    cfg = env.unwrapped.config
    return fingerprint(env.unwrapped.scenario), cfg.replace(**{f: getattr(TaskAllocConfig, f) for f in FAULT_FIELDS})


def known_values(tasks: dict[str, Any]) -> dict[tuple[str, str, TaskAllocConfig], float]:
    """Best-known values already in the reference, by (solver, instance fingerprint, fault-free config)."""
    known = {}
    for task_id, entry in tasks.items():
        if task_id not in TASKS:
            continue
        for seed, instance, value in zip(entry["seeds"], entry["instances"], entry["best_known"]):
            known[(entry["solvers"]["best_known"], instance, static_problem(task_id, seed)[1])] = value
    return known


def task_reference(task_id: str, jobs: int = 1, known: dict | None = None) -> dict[str, Any]:
    """The reference entry of one task: the three solvers' scores on every test seed. A best-known value ``known``
    already holds for the same fault-free problem (Lossy's instances are Default's) is reused, not searched again."""
    suite_task = TASKS[task_id]
    seeds = list(suite_task.test_seeds)
    solvers = {"random": "random", "normaliser": suite_task.normaliser, "best_known": suite_task.best_known}
    entry: dict[str, Any] = {"seeds": seeds, "solvers": solvers}
    for part in ("random", "normaliser"):
        rows = play_task(solvers[part], task_id, seeds, jobs=jobs)
        entry[part] = [row["score"] for row in rows]
    entry["instances"] = [row["instance"] for row in rows]
    keys = [(solvers["best_known"], instance, static_problem(task_id, seed)[1])
            for seed, instance in zip(seeds, entry["instances"])]
    known = known or {}
    missing = [seed for seed, key in zip(seeds, keys) if key not in known]
    searched = {row["seed"]: row["score"] for row in play_task(solvers["best_known"], task_id, missing, jobs=jobs)}
    entry["best_known"] = [searched[seed] if seed in searched else known[key] for seed, key in zip(seeds, keys)]
    return entry


def write_reference(task_ids: Sequence[str], jobs: int = 1, path: Path | None = None) -> Path:
    """Recompute the entries of ``task_ids`` (others already in the file are kept) and write the file."""
    path = path or reference_path()
    data = json.loads(path.read_text(encoding="utf-8")) if path.exists() else {"suite": SUITE, "tasks": {}}
    for task_id in task_ids:
        data["tasks"][task_id] = task_reference(task_id, jobs, known_values(data["tasks"]))
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")     # after each task: resumable
    return path


def means(entry: dict[str, Any], seeds: Sequence[int]) -> dict[str, Any]:
    """The reference's mean scores on ``seeds`` (a prefix of the task's test seeds): what ``task_figures`` needs."""
    index = {seed: k for k, seed in enumerate(entry["seeds"])}
    missing = [s for s in seeds if s not in index]
    if missing:
        raise ConfigError(f"seeds {missing[:5]} are not in the reference's test seeds")
    rows = [index[s] for s in seeds]
    return {"random": float(np.mean([entry["random"][k] for k in rows])),
            "random_per_seed": [entry["random"][k] for k in rows],
            "normaliser_score": float(np.mean([entry["normaliser"][k] for k in rows])),
            "best_known_score": float(np.mean([entry["best_known"][k] for k in rows])),
            "normaliser": entry["solvers"]["normaliser"], "best_known": entry["solvers"]["best_known"]}
