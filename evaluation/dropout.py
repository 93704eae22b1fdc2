"""Drop-out against never-existed: one agent fails mid-auction; the team it leaves against a team it was never in.

    taskalloc dropout                         # 100 paired seeds per algorithm, agent fails at round 3
    taskalloc dropout --episodes 20 --round 5 --jobs 2

For each seed s and algorithm (CBBA on single-agent tasks, CBGA and CBGABI on the default scenario's L_j = 4), the
instance of seed s runs three times:

* ``full``: every agent, perfect links;
* ``dropout``: agent k = s mod N_n fails at the start of round ``--round`` (``dropout_schedule = [[k, r]]``): it
  stops sending and receiving and flies nothing; the others take it for lost after ``silence_timeout`` rounds of
  silence (default 2 (D + 1)) and clear its bids, so its tasks can be re-assigned (docs/algorithm.md §4.5);
* ``never``: the same instance with agent k removed (a fixed ``Scenario`` without its row), so the team never had it.

The table pairs ``dropout`` with ``never`` seed by seed (``taskalloc.evaluation.stats.paired``: Δ with its 95 %
t-interval, p-values, share of seeds above and tied), with ``full`` for scale. The release timing is measured on the
``dropout`` run: the rounds from the failure until no live agent's table holds a bid of k, against the bound
``silence_timeout + D`` (D the diameter of the live network); the share of k's tasks at the failure that end up valid
with other agents is the re-assignment.
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from taskalloc.evaluation.episodes import default_jobs
from taskalloc.evaluation.pool import parallel_map
from taskalloc.evaluation.report import markdown_table
from taskalloc.evaluation.stats import format_mean_sd, format_p, paired
from taskalloc.policies import make_policy, rollout
from taskalloc_env import Scenario, TaskAllocConfig, TaskAllocEnv, resolve_config
from taskalloc_env.config import GENERATION_FIELDS, to_mapping
from taskalloc_env.errors import run_cli

ALGORITHMS = {"cbba": {"agents_per_task": 1}, "cbga": {}, "cbgabi": {}}
LABELS = {"cbba": "CBBA (L_j = 1)", "cbga": "CBGA (L_j = 4)", "cbgabi": "CBGABI (L_j = 4)"}
DROPOUT_FIELDS = ("dropouts", "dropout_rounds", "dropout_schedule")


def without_agent(scenario: Scenario, agent: int) -> Scenario:
    """The same instance without ``agent``: its rows of the agent arrays removed, every task kept."""
    keep = np.arange(scenario.n_agents) != agent
    return dataclasses.replace(scenario, agent_pos=scenario.agent_pos[keep], agent_speed=scenario.agent_speed[keep],
                               agent_equipment=scenario.agent_equipment[keep])


def protocol_overrides(cfg: TaskAllocConfig) -> dict[str, Any]:
    """The scoring and protocol fields of ``cfg`` (what a fixed scenario may override), drop-outs left out."""
    return {k: v for k, v in to_mapping(cfg).items() if k not in GENERATION_FIELDS and k not in DROPOUT_FIELDS}


@dataclasses.dataclass(frozen=True)
class Release:
    """How the others let go of the failed agent's bids in one run."""

    failed_at: int              # the round at whose start the agent failed
    released_at: int | None     # first round (≥ failed_at) after which no live table holds one of its bids
    bound: int                  # silence_timeout + D (D: diameter of the live network)
    held: tuple[int, ...]       # tasks on the failed agent's own path when it failed
    reassigned: int             # of ``held``, tasks valid at the end with other agents

    @property
    def rounds(self) -> int | None:
        return None if self.released_at is None else self.released_at - self.failed_at


def run_with_failure(env: TaskAllocEnv, policy: Any, seed: int, agent: int) -> tuple[Any, Release]:
    """Roll ``policy`` out in ``env`` (whose config fails ``agent``), watching the live tables round by round."""
    observations, infos = env.reset(seed=seed)
    policy.start(env, seed)
    protocol = env.unwrapped.protocol
    failed_at = next((r for r, agents in protocol.dropouts.items() if agent in agents), None)
    if failed_at is None:
        raise ValueError(f"agent {agent} does not fail in this config")
    held: tuple[int, ...] = ()
    released_at = None
    seen_round = protocol.round
    while env.agents:
        live = env.agents
        actions = policy.act({a: observations[a] for a in live}, {a: infos[a] for a in live})
        observations, _, _, _, infos = env.step(actions)
        if protocol.round != seen_round:
            seen_round = protocol.round
            if protocol.round == failed_at:         # it failed in this step: its path is frozen from here on
                held = tuple(int(j) for j in protocol.knowledge.paths[agent])
            holds = protocol.knowledge.groups.lists(agent)[protocol.alive].any()
            if protocol.round >= failed_at and released_at is None and not holds:
                released_at = protocol.round
    allocation = env.unwrapped.evaluate()
    bound = protocol.silence_timeout + protocol.live_graph.diameter
    valid = set(allocation.valid_tasks)
    reassigned = sum(j in valid for j in held)
    return allocation, Release(failed_at, released_at, bound, held, reassigned)


def run_seed(case: tuple[str, int, int, str]) -> dict[str, Any]:
    """The three runs of one (algorithm, seed, failure round, scenario) case."""
    name, seed, failure_round, scenario = case
    cfg = resolve_config(scenario, **ALGORITHMS[name])
    agent = seed % cfg.n_agents
    policy = make_policy(name)
    full_env = TaskAllocEnv(cfg, **policy.env_overrides)
    full = rollout(full_env, policy, seed=seed)
    instance = full_env.unwrapped.scenario
    drop_env = TaskAllocEnv(cfg.replace(dropout_schedule=[[agent, failure_round]]), **policy.env_overrides)
    dropped, release = run_with_failure(drop_env, policy, seed, agent)
    if not np.array_equal(drop_env.unwrapped.scenario.agent_pos, instance.agent_pos):
        raise RuntimeError(f"seed {seed}: the drop-out run drew another instance")
    never_env = TaskAllocEnv(without_agent(instance, agent), **{**protocol_overrides(cfg), **policy.env_overrides})
    never = rollout(never_env, policy, seed=seed)
    return {"algorithm": name, "seed": seed, "agent": agent, "full": full.score, "dropout": dropped.score,
            "never": never.score, "converged": dropped.converged and never.converged and full.converged,
            "release_rounds": release.rounds, "bound": release.bound, "held": len(release.held),
            "reassigned": release.reassigned, "rounds_dropout": dropped.counters.rounds,
            "rounds_never": never.counters.rounds}


def study(episodes: int, failure_round: int, jobs: int = 1, algorithms: Sequence[str] = tuple(ALGORITHMS),
          scenario: str = "default") -> list[dict[str, Any]]:
    todo = [(name, seed, failure_round, scenario) for name in algorithms for seed in range(episodes)]
    return list(parallel_map(run_seed, todo, jobs))


def tables(rows: Sequence[dict[str, Any]]) -> tuple[str, str]:
    """(scores paired: drop-out vs never-existed, release timing) as markdown."""
    scores, timing = [], []
    for name in dict.fromkeys(r["algorithm"] for r in rows):
        rs = sorted((r for r in rows if r["algorithm"] == name), key=lambda r: r["seed"])
        drop, never, full = (np.array([r[k] for r in rs]) for k in ("dropout", "never", "full"))
        pc = paired(drop, never)
        scores.append([LABELS.get(name, name), len(rs), format_mean_sd(full), format_mean_sd(drop),
                       format_mean_sd(never), f"{pc.mean_diff:+.0f} [{pc.ci95[0]:+.0f}, {pc.ci95[1]:+.0f}]",
                       f"{pc.ratio:.3f}", format_p(pc.p_t), format_p(pc.p_wilcoxon), f"{100 * pc.better:.0f} %",
                       f"{100 * pc.tied:.0f} %", sum(not r["converged"] for r in rs)])
        released = [r for r in rs if r["release_rounds"] is not None]
        delay = np.array([r["release_rounds"] for r in released])
        within = sum(r["release_rounds"] <= r["bound"] for r in released)
        held = sum(r["held"] for r in rs)
        timing.append([LABELS.get(name, name), f"{len(released)}/{len(rs)}",
                       f"{delay.mean():.1f} / {delay.max()}" if delay.size else "–",
                       f"{min(r['bound'] for r in rs)}–{max(r['bound'] for r in rs)}", f"{within}/{len(released)}",
                       f"{sum(r['reassigned'] for r in rs)}/{held}",
                       f"{np.mean([r['rounds_dropout'] for r in rs]):.1f} vs "
                       f"{np.mean([r['rounds_never'] for r in rs]):.1f}"])
    score_table = markdown_table(["algorithm", "seeds", "full team", "agent k fails", "k never existed",
                                  "Δ fails − never [95 % CI]", "ratio", "p (t)", "p (Wilcoxon)", "above", "ties",
                                  "not conv."], scores)
    timing_table = markdown_table(["algorithm", "released", "rounds to release mean / max", "bound timeout + D",
                                   "within bound", "k's tasks re-assigned", "rounds, fails vs never"], timing)
    return score_table, timing_table


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="taskalloc dropout", description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=100, help="paired seeds per algorithm (default 100)")
    parser.add_argument("--round", type=int, default=3, help="the round at whose start agent k fails (default 3)")
    parser.add_argument("--scenario", default="default", help="scenario name or YAML file (default: default)")
    parser.add_argument("--jobs", type=int, default=default_jobs(), help="worker processes (default: every core)")
    parser.add_argument("--algorithms", default=",".join(ALGORITHMS), help="comma-separated: cbba, cbga, cbgabi")
    args = parser.parse_args(argv)
    algorithms = [a.strip() for a in args.algorithms.split(",") if a.strip()]
    unknown = set(algorithms) - set(ALGORITHMS)
    if unknown:
        parser.error(f"unknown algorithms {sorted(unknown)}; known: {', '.join(ALGORITHMS)}")
    rows = study(args.episodes, args.round, args.jobs, algorithms, args.scenario)
    score_table, timing_table = tables(rows)
    print(f"agent k = seed mod N_n fails at the start of round {args.round}; {args.episodes} paired seeds "
          f"(scenario {args.scenario}):\n")
    print(score_table)
    print(timing_table)
    late = [r for r in rows if r["release_rounds"] is None or r["release_rounds"] > r["bound"]]
    return 1 if late else 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
