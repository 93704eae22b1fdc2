"""Johnson's asynchronous replan against no replan on pop-up tasks (Johnson §4.2; the trigger is ours,
``taskalloc.policies.replan``).

    python -m research.evaluation.popup_replan --episodes 100 --jobs 2
    python -m research.evaluation.popup_replan --episodes 100 --jobs 2 --set max_bundle=3

Johnson's dynamic setting, the suite's ``taskalloc/Async-v0`` config (8 agents, bundles of 5, 35 single-agent tasks:
10 at the start, then a pop-up every 50 ticks; Johnson §4.1.3; ``--set`` changes a field), seeds 0 … N−1, each
instance played by three arms: ``ACBBA`` (no replan), ``replan`` (``AsyncReplanPolicy("bundle")``: Johnson's "drop
its entire bundle") and ``replan, suffix`` (``AsyncReplanPolicy("suffix")``: from the first task the pop-up would
precede, ours). Every arm runs with ``release_actions = true`` (ACBBA never takes one, so its episodes are those
without the option).

Per episode: the score; Johnson's messages (broadcasts: "1 message being sent as an agent broadcasting some piece of
information to every vehicle that can hear it", l. 921) and the link messages; and per pop-up task the ticks from its
release to its **assignment** (the first tick its final holder, the agent with the task on its path at the end, holds
it) and until it is **settled** (the tick from which that agent holds it for good: a later replan or outbid release
that drops it, and the re-bid after, count). *Sound* counts the episodes that converged conflict-free with every
agent agreeing. A replan arm is paired with ACBBA seed by seed (``taskalloc.evaluation.stats.paired``); the times
are compared over the pop-ups both arms assign (each episode's mean over them; the median over all those pop-ups in
brackets). The replans themselves: how many, on
how many agents per pop-up, how many replanners win their pop-up, how often the pop-up enters the rebuilt bundle
ahead of every displaced task (the trigger's prediction; a task outside the bundle may come first, or a better bid
heard meanwhile take the pop-up), and where the dropped tasks end.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

import numpy as np
import yaml

from taskalloc.evaluation.episodes import default_jobs
from taskalloc.evaluation.pool import parallel_map
from taskalloc.evaluation.report import markdown_table
from taskalloc.evaluation.stats import format_mean_sd, format_p, paired
from taskalloc.policies import AsyncReplanPolicy, make_policy
from taskalloc.policies.replan import Replan
from taskalloc_env import TaskAllocEnv
from taskalloc_env.actions import ActionKind, decode
from taskalloc_env.cbba_table import NONE
from taskalloc_env.errors import run_cli
from taskalloc_env.suite import task

SUITE_TASK = "taskalloc/Async-v0"
ARMS = ("ACBBA", "replan", "replan, suffix")


def arm_policy(arm: str) -> Any:
    """The policy of ``arm``."""
    if arm == "ACBBA":
        return make_policy("acbba")
    return AsyncReplanPolicy("bundle" if arm == "replan" else "suffix")


def holding(held: np.ndarray, final: np.ndarray) -> np.ndarray:
    """(T, P) whether each pop-up's final holder holds it at each recorded tick, from ``held`` (T, N, P); False where
    the final holder is NONE."""
    return held[:, np.maximum(final, 0), np.arange(len(final))] & (final != NONE)[None, :]


def first_held(held: np.ndarray, final: np.ndarray, release: np.ndarray, ticks: np.ndarray) -> np.ndarray:
    """Per pop-up, ticks from its release to the first tick its final holder holds it (nan: none holds it)."""
    holds = holding(held, final)
    return np.where(holds.any(axis=0), ticks[holds.argmax(axis=0)] - release, np.nan).astype(float)


def settled(held: np.ndarray, final: np.ndarray, release: np.ndarray, ticks: np.ndarray) -> np.ndarray:
    """Per pop-up, ticks from its release to the tick from which its final holder holds it to the end (nan: none
    holds it)."""
    lapses = ~holding(held, final)
    last = np.where(lapses, np.arange(len(ticks))[:, None], -1).max(axis=0)
    since = np.where(last >= 0, ticks[np.maximum(last, 0)] + 1, ticks[0])
    return np.where(final == NONE, np.nan, since - release).astype(float)


def ahead_of_displaced(replan: Replan, bids: Sequence[int]) -> bool:
    """The replanner's bids after ``replan`` put its pop-up before every task it displaced (from ``precedes`` on)."""
    displaced = replan.dropped[replan.dropped.index(replan.precedes):]
    return next((j for j in bids if j == replan.popup or j in displaced), None) == replan.popup


def run_seed(case: tuple[str, int, tuple[tuple[str, Any], ...]]) -> dict[str, Any]:
    """One arm on one seed (``overrides`` on top of the suite task's config): the episode's figures, per-pop-up
    times and the replans' outcomes."""
    arm, seed, overrides = case
    policy = arm_policy(arm)
    env = TaskAllocEnv(task(SUITE_TASK).config().replace(**dict(overrides)), release_actions=True)
    observations, infos = env.reset(seed=seed)
    policy.start(env, seed)
    protocol = env.protocol
    m = env.config.n_tasks
    popups = np.flatnonzero(protocol.release_tick > 0)
    replans: list[Replan] = getattr(policy, "replans", [])
    held, ticks = [], []
    building: dict[int, tuple[Replan, list[int]]] = {}      # a replanner's bids since its replan, until its pass
    ahead = 0
    while env.agents:
        seen = len(replans)
        actions = policy.act({a: observations[a] for a in env.agents}, infos)
        for replan in replans[seen:]:
            if replan.agent in building:                     # replanned again before its build completed
                ahead += ahead_of_displaced(*building.pop(replan.agent))
            building[replan.agent] = (replan, [])
        for name, action in actions.items():
            agent = env.agent_index[name]
            kind, j = decode(action, m)
            if agent in building and kind is ActionKind.BID:
                building[agent][1].append(j)
            elif agent in building and kind is ActionKind.PASS and protocol.ready[agent]:
                ahead += ahead_of_displaced(*building.pop(agent))
        observations, _, _, _, infos = env.step(actions)
        held.append(protocol.knowledge.own_bids()[:, popups] > 0)
        ticks.append(protocol.round)
    allocation = env.evaluate()
    owner = {j: i for i, path in enumerate(allocation.paths) for j in path}
    final = np.array([owner.get(int(j), NONE) for j in popups])
    release, history, at = protocol.release_tick[popups], np.array(held), np.array(ticks)
    dropped = [(r.agent, j) for r in replans for j in r.dropped]
    c = allocation.counters
    return {"arm": arm, "seed": seed, "score": allocation.score, "broadcasts": c.broadcasts,
            "link_messages": c.messages_sent, "ticks": c.rounds,
            "sound": allocation.converged and allocation.agreement and not allocation.conflicts,
            "assign": first_held(history, final, release, at), "settle": settled(history, final, release, at),
            "assigned": int((final != NONE).sum()), "replans": len(replans),
            "replanned_popups": len({r.popup for r in replans}),
            "won": sum(owner.get(r.popup) == r.agent for r in replans), "ahead": ahead,
            "dropped": len(dropped), "kept": sum(owner.get(j) == i for i, j in dropped),
            "taken": sum(owner.get(j, i) != i for i, j in dropped)}


def study(episodes: int, jobs: int = 1, arms: Sequence[str] = ARMS,
          overrides: Sequence[tuple[str, Any]] = ()) -> list[dict[str, Any]]:
    """Every arm on seeds 0 … ``episodes`` − 1, with config ``overrides`` (field, value) on top of the suite task's."""
    cases = [(arm, seed, tuple(overrides)) for arm in arms for seed in range(episodes)]
    return list(parallel_map(run_seed, cases, jobs))


def override(text: str) -> tuple[str, Any]:
    """``--set FIELD=VALUE`` (VALUE read as YAML)."""
    key, eq, value = text.partition("=")
    if not eq:
        raise argparse.ArgumentTypeError(f"--set takes FIELD=VALUE, got {text!r}")
    return key.strip(), yaml.safe_load(value)


def common_mean(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """The means of two arms' per-pop-up times over the pop-ups both assign (nan if none)."""
    both = ~np.isnan(a) & ~np.isnan(b)
    return (float(a[both].mean()), float(b[both].mean())) if both.any() else (np.nan, np.nan)


def tables(rows: Sequence[dict[str, Any]]) -> tuple[str, str]:
    """(each replan arm paired with ACBBA: score, ticks to assignment and until settled, broadcasts; the replans) as
    markdown."""
    by = {arm: sorted((r for r in rows if r["arm"] == arm), key=lambda r: r["seed"])
          for arm in dict.fromkeys(r["arm"] for r in rows)}
    base = by["ACBBA"]
    paired_rows, replan_rows = [], []
    for arm, rs in by.items():
        if [r["seed"] for r in rs] != [r["seed"] for r in base]:
            raise ValueError(f"{arm}: not the seeds of ACBBA")
        cells = [arm, len(rs), sum(r["sound"] for r in rs)]
        for metric, digits in (("score", 1), ("assign", 1), ("settle", 0), ("broadcasts", 0)):
            if metric in ("assign", "settle"):
                means = np.array([common_mean(r[metric], b[metric]) for r, b in zip(rs, base)])
                means = means[~np.isnan(means).any(axis=1)]
                mine, theirs = means[:, 0], means[:, 1]
                pooled = np.concatenate([r[metric][~np.isnan(r[metric]) & ~np.isnan(b[metric])]
                                         for r, b in zip(rs, base)])
                cells.append(f"{format_mean_sd(mine, digits)} (median {np.median(pooled):.0f})")
            else:
                mine, theirs = (np.array([r[metric] for r in x], dtype=float) for x in (rs, base))
                cells.append(format_mean_sd(mine, digits))
            pc = paired(mine, theirs)
            cells.append("–" if arm == "ACBBA" else
                         f"{pc.mean_diff:+.{digits}f} [{pc.ci95[0]:+.{digits}f}, {pc.ci95[1]:+.{digits}f}], "
                         f"p {format_p(pc.p_t)} / {format_p(pc.p_wilcoxon)}")
        cells.append(format_mean_sd([r["assigned"] for r in rs], 1))
        paired_rows.append(cells)
        if arm == "ACBBA":
            continue
        total, dropped = (sum(r[k] for r in rs) for k in ("replans", "dropped"))

        def share(key: str, of: int, rs: list = rs) -> str:
            return f"{100 * sum(r[key] for r in rs) / max(of, 1):.0f} %"

        replan_rows.append([arm, f"{total / len(rs):.1f}",
                            f"{total / max(1, sum(r['replanned_popups'] for r in rs)):.1f}", share("won", total),
                            share("ahead", total), f"{dropped / len(rs):.1f}", share("kept", dropped),
                            share("taken", dropped)])
    header = ["arm", "seeds", "sound", "score", "Δ score [95 % CI], p (t) / (W)", "ticks to assignment", "Δ",
              "ticks until settled", "Δ", "broadcasts", "Δ", "pop-ups assigned (of 25)"]
    replan_header = ["arm", "replans per episode", "replanners per pop-up", "replanner wins its pop-up",
                     "pop-up rebuilt ahead of the displaced", "tasks dropped per episode",
                     "dropped, back with the replanner", "dropped, taken by another agent"]
    return markdown_table(header, paired_rows), markdown_table(replan_header, replan_rows)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.evaluation.popup_replan",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=100, help="paired seeds 0..N-1 (default 100)")
    parser.add_argument("--jobs", type=int, default=default_jobs(), help="worker processes (default: every core)")
    parser.add_argument("--set", dest="overrides", type=override, action="append", default=[],
                        metavar="FIELD=VALUE", help="config override on top of the suite task's, e.g. --set "
                        "max_bundle=3 (repeatable)")
    args = parser.parse_args(argv)
    if args.episodes < 2:
        parser.error(f"--episodes must be at least 2 for paired statistics, got {args.episodes}")
    task(SUITE_TASK).config().replace(**dict(args.overrides))     # a bad field fails here, before any episode
    rows = study(args.episodes, args.jobs, overrides=args.overrides)
    paired_table, replan_table = tables(rows)
    changed = "".join(f", {k}={v}" for k, v in args.overrides)
    print(f"{SUITE_TASK} (8 agents, bundles of 5, 10 tasks then 25 pop-ups, one every 50 ticks{changed}), seeds 0-"
          f"{args.episodes - 1}; times over the pop-ups both arms assign:\n")
    print(paired_table)
    print()
    print(replan_table)
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
