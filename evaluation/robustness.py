"""Robustness under message loss: random scenarios, each algorithm under independent loss, checked episode by episode.

    taskalloc robustness                                  # 1,000 scenarios per algorithm, loss 20 %
    taskalloc robustness --scenarios 50 --loss 0.3 --jobs 2

For each algorithm (CBBA on single-agent tasks; CBGA and CBGABI on mixed L_j) the command draws random scenarios
(3–10 agents, 4–20 tasks, start-time spreads, windows and durations, the L_j mixes and equipment mixes of
``taskalloc.evaluation.fuzz``, a limited communication range in 30 % of them), runs the algorithm with each message lost
independently with probability ``--loss``, and checks every episode:

* ``converged``: the episode ended by the convergence test (docs/algorithm.md §4.5), not by the round bound
  T_max = 10 · max(N_m, N_n · max L_j) · D;
* ``conflict-free``: at convergence no task has more members than L_j among the agents of one connected group (on
  a connected network: none at all; separate groups cannot know of each other, thesis §4.3, Fig 4.2);
* ``agreement``: at convergence every connected group of agents holds one table.

The same scenarios also run on perfect links, so the rounds under loss can be read against the rounds without it.
The table gives the share that converged, the rounds taken (mean, median, 95th percentile, maximum, and the mean
ratio to the perfect-link run of the same scenario), and how often the silence timeout fired (an agent taking a
neighbour it had not heard of for ``silence_timeout`` rounds for lost: ``Counters.silent_releases``). An episode
that fails a check prints its reproducer (algorithm, config, seed) and why it did not converge; the command then
exits with status 1.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from taskalloc.evaluation.episodes import default_jobs
from taskalloc.evaluation.fuzz import draw_equipment
from taskalloc.evaluation.pool import parallel_map
from taskalloc.evaluation.report import markdown_table
from taskalloc.policies import make_policy, rollout
from taskalloc_env import TaskAllocEnv
from taskalloc_env.allocation import on_paths
from taskalloc_env.errors import run_cli, seed_argument

ALGORITHMS = ("cbba", "cbga", "cbgabi")
MIXES = ([1, 2], [1, 2, 3], [2, 3], [1, 3], [1, 2, 3, 4])


def draw_config(rng: np.random.Generator, single: bool, loss: float) -> dict[str, Any]:
    """A random scenario: sizes, windows and L_j as ``taskalloc.evaluation.fuzz`` draws them (mixed L_j unless
    ``single``)."""
    n_agents, n_tasks = int(rng.integers(3, 11)), int(rng.integers(4, 21))
    kw: dict[str, Any] = {"n_agents": n_agents, "n_tasks": n_tasks, "message_loss": loss,
                          "start_time_range": [0.0, float(rng.choice([10.0, 30.0, 60.0, 100.0]))],
                          "window": float(rng.choice([2.0, 5.0, 10.0])), "duration": float(rng.choice([0.0, 5.0]))}
    if single:
        kw["agents_per_task"] = 1
    elif rng.random() < 0.25:          # equipment: a task needs one agent per item (thesis §3.1.3)
        kw.update(draw_equipment(rng, n_tasks))
    else:
        mix = [v for v in MIXES[int(rng.integers(len(MIXES)))] if v <= n_agents]
        kw["agents_per_task"] = mix if len(mix) > 1 else mix[0]
    if rng.random() < 0.3:
        kw["comm_range"] = float(rng.uniform(1.0, 4.0))
        kw["require_known_capacity"] = bool(rng.integers(2))
    return kw


def cases(scenarios: int, seed: int, loss: float,
          algorithms: Sequence[str] = ALGORITHMS) -> list[tuple[str, dict[str, Any], int]]:
    """(algorithm, config, seed) for ``scenarios`` random scenarios per algorithm; the draw depends on ``seed``."""
    out = []
    for n, name in enumerate(algorithms):
        rng = np.random.default_rng([seed, n])
        for _ in range(scenarios):
            out.append((name, draw_config(rng, name == "cbba", loss), int(rng.integers(2**31))))
    return out


def run_case(case: tuple[str, dict[str, Any], int]) -> dict[str, Any]:
    """One scenario under loss and on perfect links; the verdict of every check and the figures of both runs."""
    name, kw, seed = case
    lossy = _episode(name, kw, seed)
    perfect = _episode(name, {**kw, "message_loss": 0.0}, seed)
    return {"case": case, **lossy, "perfect_rounds": perfect["rounds"], "perfect_converged": perfect["converged"]}


def _episode(name: str, kw: dict[str, Any], seed: int) -> dict[str, Any]:
    policy = make_policy(name)
    env = TaskAllocEnv(**kw, **policy.env_overrides)
    allocation = rollout(env, policy, seed=seed)
    protocol = env.unwrapped.protocol
    out = {"converged": allocation.converged, "rounds": allocation.counters.rounds,
           "rounds_to_agreement": allocation.counters.rounds_to_agreement, "bound": protocol.max_rounds,
           "silent_releases": allocation.counters.silent_releases, "lost": allocation.counters.messages_lost,
           "sent": allocation.counters.messages_sent, "conflict_free": None, "agreement": None,
           "connected": bool((protocol.live_graph.component == 0).all()), "why": ""}
    if allocation.converged:
        out["conflict_free"] = group_conflicts(protocol) == 0
        out["agreement"] = allocation.agreement
    else:
        out["why"] = why_not_converged(protocol)
    return out


def group_conflicts(protocol: Any) -> int:
    """Tasks with more than L_j members among the live agents of one connected group (members: own flown paths)."""
    members = on_paths(protocol.flown_paths, protocol.scenario.n_tasks)
    comp = protocol.live_graph.component
    bad = 0
    for c in np.unique(comp[protocol.alive]):
        group = (comp == c) & protocol.alive
        bad += int((members[group].sum(axis=0) > protocol.scenario.task_agents).sum())
    return bad


def why_not_converged(protocol: Any) -> str:
    """What held the run at the round bound: tables still changing, a quit timer, or a quiet but unsettled state."""
    if protocol.stable_rounds == 0:
        return "tables still changing at the round bound"
    if protocol.stable_rounds < protocol.live_graph.diameter + 1:
        return f"only {protocol.stable_rounds} quiet rounds at the bound"
    return "quiet, but not every neighbour heard since the last change"


@dataclasses.dataclass
class Summary:
    """The figures of one algorithm's episodes."""

    algorithm: str
    label: str
    scenarios: int
    converged: int
    conflict_free: int
    agreement: int
    checked: int
    rounds: np.ndarray
    perfect_rounds: np.ndarray
    bound: np.ndarray
    silent: int
    loss: float

    def row(self) -> list[str]:
        r, ratio = self.rounds, self.rounds / np.maximum(self.perfect_rounds, 1)
        return [self.label, str(self.scenarios), f"{self.converged} ({100 * self.converged / self.scenarios:.1f} %)",
                f"{r.mean():.1f} / {np.median(r):.0f} / {np.percentile(r, 95):.0f} / {r.max()}",
                f"{self.perfect_rounds.mean():.1f}", f"×{ratio.mean():.2f}", f"{np.median(self.bound):.0f}",
                f"{self.conflict_free}/{self.checked}", f"{self.agreement}/{self.checked}",
                f"{self.silent} ({100 * self.silent / self.scenarios:.1f} %)", f"{100 * self.loss:.1f} %"]


HEADER = ("algorithm", "scenarios", "converged", "rounds mean / median / p95 / max", "rounds, perfect links",
          "rounds ratio", "round bound (median)", "conflict-free", "agreement", "silence timeouts",
          "messages lost")
LABELS = {"cbba": "CBBA (L_j = 1)", "cbga": "CBGA (mixed L_j)", "cbgabi": "CBGABI (mixed L_j)"}


def summarise(verdicts: Sequence[dict[str, Any]]) -> list[Summary]:
    out = []
    for name in dict.fromkeys(v["case"][0] for v in verdicts):
        vs = [v for v in verdicts if v["case"][0] == name]
        checked = [v for v in vs if v["converged"]]
        out.append(Summary(
            algorithm=name, label=LABELS.get(name, name), scenarios=len(vs), converged=len(checked),
            conflict_free=sum(bool(v["conflict_free"]) for v in checked),
            agreement=sum(bool(v["agreement"]) for v in checked), checked=len(checked),
            rounds=np.array([v["rounds"] for v in vs]), perfect_rounds=np.array([v["perfect_rounds"] for v in vs]),
            bound=np.array([v["bound"] for v in vs]), silent=sum(v["silent_releases"] > 0 for v in vs),
            loss=sum(v["lost"] for v in vs) / max(1, sum(v["sent"] for v in vs))))
    return out


def failures(verdicts: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Episodes that did not converge, or converged with a conflict or a disagreement inside a group."""
    return [v for v in verdicts if not v["converged"] or not v["conflict_free"] or not v["agreement"]]


def robustness(scenarios: int, seed: int, loss: float, jobs: int = 1,
               algorithms: Sequence[str] = ALGORITHMS) -> list[dict[str, Any]]:
    """Run every case; one verdict per (algorithm, scenario)."""
    todo = cases(scenarios, seed, loss, algorithms)
    return list(parallel_map(run_case, todo, jobs))


def report(verdicts: Sequence[dict[str, Any]]) -> str:
    return markdown_table(HEADER, [s.row() for s in summarise(verdicts)])


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="taskalloc robustness", description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenarios", type=int, default=1000, help="random scenarios per algorithm (default 1000)")
    parser.add_argument("--loss", type=float, default=0.2, help="independent message-loss rate (default 0.2)")
    parser.add_argument("--seed", type=seed_argument, default=0, help="seed of the draw of scenarios (default 0)")
    parser.add_argument("--jobs", type=int, default=default_jobs(), help="worker processes (default: every core)")
    parser.add_argument("--algorithms", default=",".join(ALGORITHMS),
                        help=f"comma-separated, from {', '.join(ALGORITHMS)}")
    args = parser.parse_args(argv)
    algorithms = [a.strip() for a in args.algorithms.split(",") if a.strip()]
    unknown = set(algorithms) - set(ALGORITHMS)
    if unknown:
        parser.error(f"unknown algorithms {sorted(unknown)}; known: {', '.join(ALGORITHMS)}")
    verdicts = robustness(args.scenarios, args.seed, args.loss, args.jobs, algorithms)
    print(f"{args.scenarios} random scenarios per algorithm, independent message loss {args.loss:g}, seed {args.seed}:")
    print()
    print(report(verdicts))
    bad = failures(verdicts)
    for v in bad[:10]:
        name, kw, seed = v["case"]
        print(f"FAILED ({v['why'] or 'conflict or disagreement at convergence'}): {name}, seed {seed}, "
              f"config {json.dumps(kw)}", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
