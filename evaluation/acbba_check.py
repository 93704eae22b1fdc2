"""ACBBA against synchronous CBBA on random static scenarios: convergence, conflicts, equal allocations.

    taskalloc acbba-check                          # 1000 scenarios, perfect links
    taskalloc acbba-check --scenarios 300 --faults "{message_loss: 0.2, max_delay: 3}"

Each seed draws a static scenario with single-agent tasks and DMG scores (``marginal_gain="frozen"``,
``distance_cost="from_start"``: Johnson §3.4.1, eq. (3.13)), 2–8 agents and 3–15 tasks, and runs ACBBA
(``consensus="acbba"``, the scripted ``acbba`` policy) and synchronous CBBA on the same instance. It counts: ACBBA
converged (the network went quiet before T_max), agreement (every agent holds the same table), conflict-free (no
task in two bundles), and, on perfect links, whether ACBBA's allocation equals CBBA's.

A difference must be explained by the stated rule of docs/decisions.md ("CBBA = SGA holds except after stale
information"): one of the two runs differs from the centralised greedy SGA (``taskalloc.policies.sgama``) *and* in that
run an agent bid while a task it valued more was blocked only by a record of a bid its holder had already released.
Every other difference is reported as unexplained (and the command exits with status 1). With ``--faults`` the verdict
needs convergence and conflict-freedom; agreement is reported (a bid can stay unknown to an agent when its broadcast and
every confirmation to that agent are lost, docs/decisions.md).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np
import yaml

from taskalloc.evaluation.episodes import default_jobs
from taskalloc.evaluation.pool import parallel_map
from taskalloc.policies import make_policy, sgama
from taskalloc_env import TaskAllocEnv
from taskalloc_env.allocation import Allocation
from taskalloc_env.cbba_table import NONE
from taskalloc_env.errors import run_cli


def scenario(seed: int) -> dict[str, Any]:
    """The config of static scenario ``seed``: DMG scores, single-agent tasks, every agent hears every other."""
    rng = np.random.default_rng(seed)
    return {"n_agents": int(rng.integers(2, 9)), "n_tasks": int(rng.integers(3, 16)), "agents_per_task": 1,
            "distance_cost": "from_start", "marginal_gain": "frozen", "start_time_range": (0.0, 30.0)}


def stale_blocked(env: TaskAllocEnv) -> bool:
    """Some agent that may bid now values a task more than every bid open to it, and that task is blocked only by a
    record naming a holder whose own table no longer holds it (the stale information of docs/decisions.md)."""
    p = env.protocol
    view, kn = p.view(), p.knowledge
    own = kn.own_bids()
    for a in env.agents:
        i = env.agent_index[a]
        if env.config.asynchronous and not p.ready[i]:
            continue
        best = np.max(np.where(view.can_bid[i], view.gain[i], 0.0))
        holders = kn.winner[i]
        blocked = view.eligible[i] & (view.gain[i] > best) & (holders != NONE) & (holders != i)
        if np.any(own[holders[blocked], np.flatnonzero(blocked)] <= 0):
            return True
    return False


def run(env: TaskAllocEnv, policy: str, seed: int) -> tuple[Allocation, bool]:
    """One episode; also whether stale information blocked a better bid at some step."""
    agent = make_policy(policy)
    obs, infos = env.reset(seed=seed)
    agent.start(env, seed)
    stale = False
    while env.agents:
        stale = stale or stale_blocked(env)
        obs, _, _, _, infos = env.step(agent.act({a: obs[a] for a in env.agents}, infos))
    return env.evaluate(), stale


@dataclasses.dataclass(frozen=True)
class Verdict:
    seed: int
    converged: bool
    agreement: bool
    conflict_free: bool
    equal: bool | None              # ACBBA's paths = CBBA's (None: not compared, faulty links)
    explained: bool | None          # a difference with a stale-information run that differs from SGA
    broadcasts: int
    quiet_tick: int


def check(args: tuple[int, dict[str, Any]]) -> Verdict:
    seed, faults = args
    cfg = {**scenario(seed), **faults}
    acbba, acbba_stale = run(TaskAllocEnv(**cfg, consensus="acbba"), "acbba", seed)
    equal = explained = None
    if not faults:
        cbba_env = TaskAllocEnv(**cfg)
        cbba, cbba_stale = run(cbba_env, "cbba", seed)
        equal = acbba.paths == cbba.paths
        if not equal:
            greedy = sgama(cbba_env.scenario, cbba_env.config).paths
            explained = (acbba_stale and acbba.paths != greedy) or (cbba_stale and cbba.paths != greedy)
    return Verdict(seed, acbba.converged, acbba.agreement, not acbba.conflicts, equal, explained,
                   acbba.counters.broadcasts, acbba.counters.quiet_tick)


def run_checks(scenarios: int, faults: dict[str, Any], jobs: int, first: int = 0) -> list[Verdict]:
    todo = [(seed, faults) for seed in range(first, first + scenarios)]
    return list(parallel_map(check, todo, jobs))


def report(verdicts: Sequence[Verdict]) -> tuple[str, bool]:
    """The printed counts, and whether every check passed."""
    counts = Counter()
    for v in verdicts:
        counts["converged"] += v.converged
        counts["agreement"] += v.agreement
        counts["conflict-free"] += v.conflict_free
        counts["equal"] += v.equal is True
        counts["differ, explained"] += v.equal is False and bool(v.explained)
        counts["differ, unexplained"] += v.equal is False and not v.explained
    n = len(verdicts)
    lines = [f"{n} static scenarios (seeds {verdicts[0].seed}–{verdicts[-1].seed}):" if n else "no scenarios"]
    for key in ("converged", "agreement", "conflict-free"):
        lines.append(f"  ACBBA {key:<14} {counts[key]:>5} / {n}")
    for key, name in (("converged", "not converged"), ("agreement", "not in agreement"),
                      ("conflict_free", "with conflicts")):
        odd = [v.seed for v in verdicts if not getattr(v, key)]
        if odd:
            lines.append(f"  seeds {name}: {odd[:20]}{' …' if len(odd) > 20 else ''}")
    if any(v.equal is not None for v in verdicts):
        lines.append(f"  ACBBA = CBBA         {counts['equal']:>5} / {n}")
        lines.append(f"  differ, explained    {counts['differ, explained']:>5}   (stale information, a run ≠ SGA)")
        lines.append(f"  differ, unexplained  {counts['differ, unexplained']:>5}")
        odd = [v.seed for v in verdicts if v.equal is False]
        if odd:
            lines.append(f"  seeds that differ: {odd[:20]}{' …' if len(odd) > 20 else ''}")
    broadcasts = [v.broadcasts for v in verdicts]
    ticks = [v.quiet_tick for v in verdicts if v.converged]
    if broadcasts:
        lines.append(f"  broadcasts: median {np.median(broadcasts):.0f}, max {max(broadcasts)}; quiet at tick: "
                     f"median {np.median(ticks) if ticks else float('nan'):.0f}, max {max(ticks, default=0)}")
    faulty = all(v.equal is None for v in verdicts)
    ok = (counts["converged"] == counts["conflict-free"] == n and (faulty or counts["agreement"] == n)
          and counts["differ, unexplained"] == 0)
    return "\n".join(lines), ok


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="taskalloc acbba-check", description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenarios", type=int, default=1000, help="random static scenarios (default 1000)")
    parser.add_argument("--first", type=int, default=0, help="the first seed (default 0)")
    parser.add_argument("--faults", type=yaml.safe_load, default={},
                        help='network options as YAML, e.g. "{message_loss: 0.2, max_delay: 3}" (no CBBA comparison)')
    parser.add_argument("--jobs", type=int, default=default_jobs(), help="worker processes (default: every core)")
    args = parser.parse_args(argv)
    text, ok = report(run_checks(args.scenarios, dict(args.faults or {}), args.jobs, args.first))
    print(text)
    if not ok:
        print("FAILED: see the counts above", file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
