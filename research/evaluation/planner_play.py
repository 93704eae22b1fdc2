"""How a learned round-0 planner's play rule moves its score: its threshold, and replanning or planning once (ours).

    python -m research.evaluation.planner_play --planner learned:runs/planner_small_attention/seed0 \
        --thresholds 0.3 0.5 0.7

``research.policies.round_zero.RoundZeroPlanner`` bids in round 0 on the allowed tasks whose estimated probability of
being on the agent's path is at least a threshold, then hands over to the policy its checkpoint names. It either
estimates afresh at every step (``replan``, the default) or plans once at the agent's first round-0 state, the local
plan's way. This table plays the same weights with every threshold given and both rules, next to the follower alone, on
the same instances (seed s is the same instance for every row): mean score, its share of the follower's, and the paired
t-test against the follower. The seeds default to validation instances (``taskalloc.evaluation.seeds``), as the rule is
chosen there and not on the held-out ones.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import numpy as np

from research.plugins import planner_pair
from research.policies.handover import Handover
from research.policies.round_zero import is_threshold
from taskalloc.evaluation.episodes import evaluate
from taskalloc.evaluation.seeds import VALIDATION_SEED_START
from taskalloc.evaluation.stats import format_p, paired
from taskalloc_env.config import resolve_config
from taskalloc_env.errors import ConfigError, run_cli


def main(argv: Sequence[str] | None = None) -> str:
    parser = argparse.ArgumentParser(prog="python -m research.evaluation.planner_play", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--planner", required=True, metavar="NAME",
                        help="a round-0 planner's policy name, learned:<checkpoint>")
    parser.add_argument("--thresholds", type=float, nargs="+", default=[0.5], metavar="P",
                        help="thresholds to play, each in (0, 1) (default 0.5)")
    parser.add_argument("--scenario", default="train_small", help="scenario name or YAML path (default train_small)")
    parser.add_argument("--seed-start", type=int, default=VALIDATION_SEED_START,
                        help=f"first seed (default {VALIDATION_SEED_START}, the validation instances)")
    parser.add_argument("--episodes", type=int, default=100, help="number of instances (default 100)")
    args = parser.parse_args(argv)
    if args.episodes < 2:
        raise ConfigError(f"--episodes: got {args.episodes}; allowed: an integer >= 2 (a paired test needs two)")
    bad = [t for t in args.thresholds if not is_threshold(t)]
    if bad:
        raise ConfigError(f"--thresholds: got {bad}; allowed: numbers in (0, 1)")
    pair = planner_pair(args.planner, "--planner")
    planner, follower = pair.first, pair.then
    seeds = list(range(args.seed_start, args.seed_start + args.episodes))
    env_kwargs = {"scenario": resolve_config(args.scenario)}
    alone = np.array([a.score for a in evaluate(follower, env_kwargs, seeds)])
    lines = [f"{args.scenario}, seeds {seeds[0]}–{seeds[-1]}: {args.planner} in round 0, then {follower.name}", "",
             "| round 0 | threshold | score | % of the follower alone | Δ (p) |", "|---|--:|--:|--:|--:|",
             f"| {follower.name} alone | – | {alone.mean():.1f} | 100.0 % | – |"]
    for threshold in args.thresholds:
        for replan in (True, False):
            played = Handover(planner.with_rule(threshold, replan), follower, 1)
            scores = np.array([a.score for a in evaluate(played, env_kwargs, seeds)])
            test = paired(scores, alone)
            lines.append(f"| {'replanning' if replan else 'planned once'} | {threshold:g} | {scores.mean():.1f} | "
                         f"{100 * test.ratio:.1f} % | {test.mean_diff:+.1f} ({format_p(test.p_t)}) |")
    table = "\n".join(lines)
    print(table)
    return table


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
