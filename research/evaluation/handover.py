"""Where a policy loses to the optimum, round by round: the oracle hands over to the policy, or the reverse.

    python -m research.evaluation.handover --policy learned:mappo_small_pooling_1m --policy cbgabi --rounds 1 2 3

For each policy P and each K in ``--rounds`` it plays the same held-out instances three ways: P alone; the
privileged ``oracle`` (``research.policies.oracle``: every agent bids along the exact optimum's path) for the first K
rounds, then P; P for the first K rounds, then the oracle. The hand-over to P shows how close P comes to the
optimum after an optimal start (what P's later rounds lose), the hand-over from P how far an optimal continuation
gets from P's start (what P's first rounds commit it to; the oracle never quits, so it cannot undo a bid). A round
is the protocol's round (``info["round"]``): under the synchronous protocols every agent's bids up to its pass,
then the consensus (thesis Alg 5); round 0 is played before any message is exchanged. Under ``acbba`` it is a tick.
Scores are divided by the exact optimum's mean (``taskalloc.policies.centralised.exact``), so the scenario must be small
enough for it (``train_small``); with ``--reference lns`` the oracle bids along the group search's allocation
(``taskalloc.policies.local_search``, a lower bound on the optimum) and scores are divided by its mean, at any size:

    python -m research.evaluation.handover --scenario default --reference lns --policy cbgabi --rounds 1 2 --episodes 50

docs/learning.md ("What stands between …") quotes these tables.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import numpy as np

from research.policies.handover import Handover
from research.policies.oracle import OraclePolicy
from taskalloc.evaluation.episodes import evaluate, skip_reason, solve
from taskalloc.evaluation.seeds import add_heldout_arguments, heldout_seeds
from taskalloc.policies import Policy, make_policy
from taskalloc_env.allocation import Allocation
from taskalloc_env.config import resolve_config
from taskalloc_env.env import TaskAllocEnv
from taskalloc_env.errors import ConfigError, run_cli


def played(policy: Policy, scenario: str, seeds: Sequence[int]) -> list[Allocation]:
    """``policy``'s allocation of each seed of ``scenario`` (its environment built with the policy's overrides)."""
    return evaluate(policy, {"scenario": scenario}, seeds)


REFERENCES = {"exact": "exact optimum", "lns": "LNS"}     # the solver the oracle follows: its label in the table


def reference_allocations(scenario: str, seeds: Sequence[int], reference: str = "exact") -> list[Allocation]:
    """The reference solver's allocation of each seed's instance (the exact optimum, or LNS's lower bound on it)."""
    env = TaskAllocEnv(scenario)
    return [solve(reference, env, int(s)) for s in seeds]


def groups_kept(allocations: Sequence[Allocation], best: Sequence[Allocation]) -> np.ndarray:
    """Per instance, the reference's valid tasks that end valid with the same members."""
    return np.array([sum(1 for j in b.valid_tasks if j in a.valid_tasks and set(a.members[j]) == set(b.members[j]))
                     for a, b in zip(allocations, best)])


def rows(policy: str, scenario: str, rounds: Sequence[int], seeds: Sequence[int],
         reference: str = "exact") -> list[tuple[str, list[Allocation]]]:
    """(label, allocations) of ``policy`` alone and handed over to / from the oracle after each number of rounds."""
    out = [(policy, played(make_policy(policy), scenario, seeds))]
    for k in rounds:
        out.append((f"oracle for {k} round(s), then {policy}",
                    played(Handover(OraclePolicy(reference), make_policy(policy), k), scenario, seeds)))
        out.append((f"{policy} for {k} round(s), then the oracle",
                    played(Handover(make_policy(policy), OraclePolicy(reference), k), scenario, seeds)))
    return out


def markdown(table: Sequence[tuple[str, Sequence[Allocation]]], best: Sequence[Allocation],
             reference: str = "exact") -> str:
    """Mean score, % of the reference's mean, the instances where the row reaches the reference's score, and how
    many of the reference's groups (valid tasks and their members) it keeps."""
    name = REFERENCES[reference]
    reached = "at the optimum" if reference == "exact" else f"at {name} or above"
    top = np.array([b.score for b in best])
    lines = [f"| row | score | % of {name} | {reached} (of {len(best)}) | {name}'s groups kept (mean) |",
             "|---|--:|--:|--:|--:|",
             f"| {name} | {top.mean():.1f} | 100.0 % | {len(best)} | {np.mean([b.n_valid for b in best]):.1f} |"]
    for label, allocations in table:
        s = np.array([a.score for a in allocations])
        at = int((np.isclose(s, top, rtol=1e-9, atol=1e-6) | (s > top)).sum())
        lines.append(f"| {label} | {s.mean():.1f} | {100 * s.mean() / top.mean():.1f} % | {at} | "
                     f"{groups_kept(allocations, best).mean():.1f} |")
    return "\n".join(lines)


def add_table_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of every hand-over table: ``--scenario``, ``--policy``, ``--reference`` and the held-out seeds."""
    parser.add_argument("--scenario", default="train_small", help="scenario name or YAML path (default train_small)")
    parser.add_argument("--policy", action="append", metavar="NAME",
                        help="a policy name (repeatable; default: learned:mappo_small_pooling_1m and cbgabi)")
    parser.add_argument("--reference", choices=sorted(REFERENCES), default="exact",
                        help="the solver the privileged part follows and scores are divided by: the exact optimum "
                             "(default; small instances only) or LNS, a lower bound on it at any size")
    add_heldout_arguments(parser)


def checked_table_arguments(args: argparse.Namespace) -> tuple[list[int], list[str]]:
    """The held-out seeds and the policy names, once the reference fits the scenario and every name loads."""
    seeds = heldout_seeds(args)
    reason = skip_reason(args.reference, resolve_config(args.scenario))
    if reason:
        raise ConfigError(f"--scenario {args.scenario}: {reason} (--reference lns plays at any size)")
    policies = args.policy or ["learned:mappo_small_pooling_1m", "cbgabi"]
    for name in policies:
        try:
            make_policy(name)
        except ValueError as exc:       # a CheckpointError is a ConfigError already
            raise ConfigError(f"--policy {name}: {exc}") from None
    return seeds, policies


def main(argv: Sequence[str] | None = None) -> str:
    parser = argparse.ArgumentParser(prog="python -m research.evaluation.handover", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, nargs="+", default=[1, 2, 3], help="hand-over rounds (default 1 2 3)")
    add_table_arguments(parser)
    args = parser.parse_args(argv)
    if min(args.rounds) < 1:
        raise ConfigError(f"--rounds: got {args.rounds}; allowed: integers >= 1")
    seeds, policies = checked_table_arguments(args)
    best = reference_allocations(args.scenario, seeds, args.reference)
    table = markdown([row for name in policies for row in rows(name, args.scenario, args.rounds, seeds,
                                                               args.reference)], best, args.reference)
    print(f"{args.scenario}, seeds {seeds[0]}–{seeds[-1]}\n\n{table}")
    return table


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
