"""Episodes of the suite's tasks: one solver (a policy name, an import path, ``learned:…``, or a centralised solver)
on one task's seeds, with the environment ``pettingzoo.make(task_id)`` builds plus the policy's ``env_overrides``.

The rollout itself is the project's (``taskalloc.evaluation.episodes.solve``); this module only builds each task's
environment with the chosen ``invalid_action`` mode and keeps the figures the benchmark reports.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

from taskalloc.evaluation.episodes import CENTRALISED, fingerprint, policy_for, solve
from taskalloc.evaluation.pool import parallel_map
from taskalloc_env import TaskAllocEnv
from taskalloc_env.errors import InvalidActionError
from taskalloc_env.suite import task

ROW_FIELDS = ("task", "solver", "seed", "instance", "score", "valid_tasks", "invalid_actions", "rounds", "messages",
              "converged")


@functools.cache
def task_env(solver: str, task_id: str, invalid_action: str = "noop") -> TaskAllocEnv:
    """One environment per (solver, task, mode) and process: the task's config plus the policy's overrides."""
    cfg = task(task_id).config()
    overrides = {} if solver.lower() in CENTRALISED else policy_for(solver).env_overrides
    return TaskAllocEnv(cfg, invalid_action=invalid_action, **overrides)


def play(job: tuple[str, str, int, str]) -> dict[str, Any]:
    """One episode ``(solver, task_id, seed, invalid_action)``: its row of ``ROW_FIELDS``."""
    solver, task_id, seed, invalid_action = job
    env = task_env(solver, task_id, invalid_action)
    try:
        allocation = solve(solver, env, seed)
    except InvalidActionError as exc:
        raise InvalidActionError(f"{task_id}, seed {seed}: {exc}") from None
    figures = allocation.summary()
    return {"task": task_id, "solver": solver, "seed": seed, "instance": fingerprint(env.unwrapped.scenario),
            "score": float(figures["score"]), "valid_tasks": figures["valid_tasks"],
            "invalid_actions": figures.get("invalid_actions") or 0, "rounds": figures.get("rounds"),
            "messages": figures.get("messages"), "converged": bool(figures["converged"])}


def play_task(solver: str, task_id: str, seeds: Sequence[int], invalid_action: str = "noop",
              jobs: int = 1) -> list[dict[str, Any]]:
    """``solver`` on every seed of ``task_id`` (in ``jobs`` processes), rows in seed order. The exact optimum runs
    only where the suite takes it as the best known (elsewhere it would not finish): a ``ValueError`` there."""
    if solver.lower() == "exact" and task(task_id).best_known != "exact":
        raise ValueError(f"exact runs only on the tasks whose best known is the exact optimum, not on {task_id} "
                         f"(best known: {task(task_id).best_known})")
    return list(parallel_map(play, [(solver, task_id, int(s), invalid_action) for s in seeds], jobs))
