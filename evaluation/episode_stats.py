"""How long whole episodes are and what they return, on the suite's tasks: the measurement behind the default step
limit ``max_cycles`` and the default ``reward_scale`` (docs/decisions.md).

    python -m evaluation.episode_stats                         # every task, all its test seeds, 2 processes
    python -m evaluation.episode_stats --tasks Small Default --episodes 10 --jobs 1

Every policy of ``POLICIES`` that applies (ACBBA only where every L_j = 1; a learned model only where its observation
fits) plays every test seed of each task in the task's environment with its ``env_overrides``, with no step limit
but the round bound (``max_cycles = step_bound``, the most steps T_max rounds can take). Per task and policy: the
most and the mean steps, the most rounds, the mean, least and most return under the default scale (the score over
the instance's total task reward, ``taskalloc_env.rewards``), and the default ``max_cycles`` over the most steps
(the margin; below 1 the default would have cut an episode).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

import numpy as np

from taskalloc.evaluation.episodes import policy_for, skip_reason
from taskalloc.evaluation.pool import parallel_map
from taskalloc_env import TaskAllocEnv
from taskalloc_env.errors import run_cli
from taskalloc_env.suite import TASKS, task

POLICIES = ("random", "cbga", "cbgabi", "acbba", "learned:mappo_small_pooling_1m", "learned:train_small")
SCRIPTED = ("random", "cbga", "cbgabi", "acbba")


def play(job: tuple[str, str, int]) -> dict[str, Any]:
    """One episode ``(task_id, policy, seed)`` without a step limit: its steps, rounds, return and whether the
    default ``max_cycles`` would have cut it."""
    task_id, name, seed = job
    policy = policy_for(name)
    env = TaskAllocEnv(task(task_id).config(), **policy.env_overrides)
    default_limit = env.max_cycles
    env.max_cycles = env.step_bound                  # the round bound alone: the episode's own length
    observations, infos = env.reset(seed=seed)
    policy.start(env, seed)
    steps = 0
    while env.agents:
        observations, _, _, _, infos = env.step(policy.act(observations, infos))
        steps += 1
    allocation = env.evaluate()
    return {"task": task_id, "policy": name, "seed": seed, "steps": steps, "rounds": allocation.counters.rounds,
            "return": allocation.score / env.reward_scale, "max_cycles": default_limit,
            "round_bound": env.round_bound}


def applies(task_id: str, name: str) -> str | None:
    """Why ``name`` cannot play ``task_id`` (None if it can)."""
    cfg = task(task_id).config()
    reason = skip_reason(name, cfg)
    if reason or not name.startswith("learned:"):
        return reason
    env = TaskAllocEnv(cfg, **policy_for(name).env_overrides)
    env.reset(seed=0)
    try:
        policy_for(name).start(env, 0)
    except ValueError as exc:                        # a learned model trained on other observation features
        return str(exc).split(";")[0]
    return None


def measure(task_ids: Sequence[str], policies: Sequence[str], episodes: int | None, jobs: int
            ) -> list[dict[str, Any]]:
    """One summary row per (task, policy) that applies, over the first ``episodes`` test seeds (all: None)."""
    jobs_list, pairs = [], []
    for task_id in task_ids:
        for name in policies:
            if applies(task_id, name) is None:
                pairs.append((task_id, name))
                seeds = task(task_id).test_seeds[:episodes]
                jobs_list += [(task_id, name, seed) for seed in seeds]
    rows = list(parallel_map(play, jobs_list, jobs))
    summary = []
    for task_id, name in pairs:
        mine = [r for r in rows if r["task"] == task_id and r["policy"] == name]
        steps, returns = [r["steps"] for r in mine], [r["return"] for r in mine]
        summary.append({"task": task_id, "policy": name, "episodes": len(mine), "max_steps": max(steps),
                        "mean_steps": float(np.mean(steps)), "max_rounds": max(r["rounds"] for r in mine),
                        "mean_return": float(np.mean(returns)), "min_return": min(returns),
                        "max_return": max(returns), "max_cycles": mine[0]["max_cycles"],
                        "round_bound": mine[0]["round_bound"], "margin": mine[0]["max_cycles"] / max(steps)})
    return summary


def markdown(summary: Sequence[dict[str, Any]]) -> str:
    head = ["task", "policy", "episodes", "steps: max", "mean", "rounds: max", "return: mean", "min", "max",
            "default max_cycles", "margin"]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join([":--", ":--"] + ["--:"] * (len(head) - 2)) + "|"]
    for r in summary:
        lines.append(f"| {r['task']} | {r['policy']} | {r['episodes']} | {r['max_steps']} | {r['mean_steps']:.1f} | "
                     f"{r['max_rounds']} | {r['mean_return']:.3f} | {r['min_return']:.3f} | {r['max_return']:.3f} | "
                     f"{r['max_cycles']} | {r['margin']:.1f} |")
    return "\n".join(lines)


def by_task(summary: Sequence[dict[str, Any]]) -> str:
    """Per task: T_max, the default limit, the longest episode of a scripted baseline and of a learned policy (in
    steps and in multiples of T_max), and the smallest margin."""
    lines = ["| task | T_max | default max_cycles | longest, scripted | longest, learned | smallest margin |",
             "|:--|--:|--:|--:|--:|--:|"]
    for task_id in dict.fromkeys(r["task"] for r in summary):
        rows = [r for r in summary if r["task"] == task_id]
        bound = rows[0]["round_bound"]
        cells = []
        for group in ([r for r in rows if r["policy"] in SCRIPTED], [r for r in rows if r["policy"] not in SCRIPTED]):
            top = max(group, key=lambda r: r["max_steps"], default=None)
            cells.append("–" if top is None else
                         f"{top['max_steps']} ({top['policy'].removeprefix('learned:')}, "
                         f"{top['max_steps'] / bound:.2f}·T_max)")
        lines.append(f"| {task_id} | {bound} | {rows[0]['max_cycles']} | {cells[0]} | {cells[1]} | "
                     f"{min(r['margin'] for r in rows):.1f} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m evaluation.episode_stats", description=__doc__.split("\n")[0])
    parser.add_argument("--tasks", nargs="+", default=[t.removeprefix("taskalloc/").removesuffix("-v0")
                                                       for t in TASKS], help="task names (default: every task)")
    parser.add_argument("--policies", nargs="+", default=list(POLICIES))
    parser.add_argument("--episodes", type=int, default=None, help="first N test seeds of each task (default: all)")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args(argv)
    task_ids = [task(name if "/" in name else f"taskalloc/{name}-v0").id for name in args.tasks]
    summary = measure(task_ids, args.policies, args.episodes, args.jobs)
    print(markdown(summary))
    print()
    print(by_task(summary))
    worst = min(summary, key=lambda r: r["margin"])
    print(f"\nsmallest margin: {worst['margin']:.1f} ({worst['task']}, {worst['policy']}: {worst['max_steps']} "
          f"steps, default max_cycles {worst['max_cycles']})")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
