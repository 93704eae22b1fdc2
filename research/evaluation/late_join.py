"""A late joiner against a team that had the agent from the start (``join_at``; ours: Johnson §2.2 and ch. 4's goal 4
let agents "enter and leave the network" but give no rule for it).

    python -m research.evaluation.late_join --episodes 100 --jobs 2

For each scenario (``default``: 10 agents, 20 tasks, L_j = 4; ``train_small``, the suite's Small: 4 agents, 8 tasks,
L_j from {1, 2}), algorithm (CBGA, CBGABI; synchronous consensus) and seed s = 0 … N−1, the instance of seed s runs
with agent k = s mod N_n present from the start, and with k joining at the start of round r for each ``--rounds``
(default 1, 3, 5): absent before r, knowing nothing but what it hears after (docs/algorithm.md, late joiners). The
instance is the same in every run (``join_at`` draws nothing; checked). Each join round is paired with the
from-the-start run seed by seed (``taskalloc.evaluation.stats.paired``): the score, the rounds until the run ends
(D + 1 quiet rounds after the last change, the protocol's stop) and until the last change, the messages received,
and what k holds at the end: the tasks on its path, those of them that are valid (paid), and how many of them it
also held when present from the start.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

import numpy as np

from taskalloc.evaluation.episodes import default_jobs
from taskalloc.evaluation.pool import parallel_map
from taskalloc.evaluation.report import markdown_table
from taskalloc.evaluation.stats import format_mean_sd, format_p, paired
from taskalloc.policies import make_policy, rollout
from taskalloc_env import TaskAllocEnv, resolve_config
from taskalloc_env.allocation import Allocation
from taskalloc_env.errors import run_cli

SCENARIOS = ("default", "train_small")
ALGORITHMS = {"cbga": "CBGA", "cbgabi": "CBGABI"}
ROUNDS = (1, 3, 5)
PRESENT = 0             # the join round of the run where the agent is there from the start


def joiner_figures(allocation: Allocation, agent: int) -> dict[str, Any]:
    """The run's figures and what ``agent`` holds at the end."""
    c = allocation.counters
    path = allocation.paths[agent]
    return {"score": allocation.score, "rounds": c.rounds, "agreement_round": c.rounds_to_agreement,
            "messages": c.messages, "converged": allocation.converged, "path": tuple(path),
            "held": len(path), "valid_held": sum(j in set(allocation.valid_tasks) for j in path)}


def run_seed(case: tuple[str, str, int, tuple[int, ...]]) -> list[dict[str, Any]]:
    """One (scenario, algorithm, seed): the from-the-start run and one run per join round."""
    scenario, name, seed, rounds = case
    cfg = resolve_config(scenario)
    agent = seed % cfg.n_agents
    policy = make_policy(name)
    rows, instance = [], None
    for join in (PRESENT, *rounds):
        env = TaskAllocEnv(cfg.replace(join_at={agent: join}) if join else cfg, **policy.env_overrides)
        allocation = rollout(env, policy, seed=seed)
        if instance is None:
            instance = env.scenario
        elif not (np.array_equal(env.scenario.agent_pos, instance.agent_pos)
                  and np.array_equal(env.scenario.task_pos, instance.task_pos)):
            raise RuntimeError(f"{scenario} seed {seed}: the run joining at round {join} drew another instance")
        rows.append({"scenario": scenario, "algorithm": name, "seed": seed, "agent": agent, "join": join,
                     **joiner_figures(allocation, agent)})
    return rows


def study(episodes: int, jobs: int = 1, scenarios: Sequence[str] = SCENARIOS,
          algorithms: Sequence[str] = tuple(ALGORITHMS), rounds: Sequence[int] = ROUNDS) -> list[dict[str, Any]]:
    """Every case on seeds 0 … ``episodes`` − 1."""
    cases = [(sc, name, seed, tuple(rounds)) for sc in scenarios for name in algorithms for seed in range(episodes)]
    return [row for rows in parallel_map(run_seed, cases, jobs) for row in rows]


def table(rows: Sequence[dict[str, Any]]) -> str:
    """One row per (scenario, algorithm, join round) as markdown; each join round paired with the from-the-start run
    (score: Δ with its 95 % interval and p-values; rounds and messages: mean and Δ)."""
    body = []
    for scenario, name in dict.fromkeys((r["scenario"], r["algorithm"]) for r in rows):
        runs = {join: sorted((r for r in rows if (r["scenario"], r["algorithm"], r["join"]) == (scenario, name, join)),
                             key=lambda r: r["seed"])
                for join in dict.fromkeys(r["join"] for r in rows)}
        base = runs[PRESENT]
        for join, rs in runs.items():
            if [r["seed"] for r in rs] != [r["seed"] for r in base]:
                raise ValueError(f"{scenario} {name} join {join}: not the seeds of the from-the-start run")

            def values(metric: str, rs: list = rs) -> np.ndarray:
                return np.array([r[metric] for r in rs], dtype=float)

            cells = [scenario, ALGORITHMS.get(name, name), "from the start" if join == PRESENT else f"round {join}",
                     len(rs), format_mean_sd(values("score"))]
            if join == PRESENT:
                cells += ["–", "–"]
            else:
                pc = paired(values("score"), values("score", base))
                cells += [f"{pc.mean_diff:+.0f} [{pc.ci95[0]:+.0f}, {pc.ci95[1]:+.0f}] ({100 * (pc.ratio - 1):+.1f} %)",
                          f"{format_p(pc.p_t)} / {format_p(pc.p_wilcoxon)}"]
            for metric, digits in (("rounds", 1), ("agreement_round", 1), ("messages", 0)):
                delta = values(metric).mean() - values(metric, base).mean()
                cells.append(f"{values(metric).mean():.{digits}f}"
                             + ("" if join == PRESENT else f" ({delta:+.{digits}f})"))
            cells.append(f"{values('held').mean():.2f} ({values('valid_held').mean():.2f})")
            same = sum(len(set(r["path"]) & set(b["path"])) for r, b in zip(rs, base))
            cells += ["–" if join == PRESENT else f"{same}/{int(values('held', base).sum())}",
                      f"{100 * np.mean(values('held') == 0):.0f} %", sum(not r["converged"] for r in rs)]
            body.append(cells)
    header = ["scenario", "algorithm", "agent k joins", "seeds", "score", "Δ score [95 % CI]", "p (t) / (W)",
              "rounds to the end (Δ)", "rounds to the last change (Δ)", "messages received (Δ)",
              "tasks k holds (valid)", "k's tasks from the start it holds again", "k holds nothing", "not conv."]
    return markdown_table(header, body, "lll" + "r" * (len(header) - 3))


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.evaluation.late_join",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=100, help="paired seeds 0..N-1 (default 100)")
    parser.add_argument("--rounds", type=int, nargs="+", default=list(ROUNDS),
                        help="the rounds agent k joins at (default 1 3 5)")
    parser.add_argument("--scenarios", nargs="+", default=list(SCENARIOS), help="scenario names or YAML files")
    parser.add_argument("--jobs", type=int, default=default_jobs(), help="worker processes (default: every core)")
    args = parser.parse_args(argv)
    if args.episodes < 2:
        parser.error(f"--episodes must be at least 2 for paired statistics, got {args.episodes}")
    if any(r < 1 for r in args.rounds):
        parser.error(f"--rounds must be rounds >= 1 (round 0 is the start), got {args.rounds}")
    for scenario in args.scenarios:                  # a bad name or join round fails here, before any episode
        resolve_config(scenario).replace(join_at={0: max(args.rounds)})
    rows = study(args.episodes, args.jobs, args.scenarios, rounds=args.rounds)
    print(f"agent k = seed mod N_n joins at the start of round r, against the same instance with k present from the "
          f"start; {args.episodes} paired seeds, synchronous consensus:\n")
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
