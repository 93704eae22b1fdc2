"""How close a round 0 played from one agent's own knowledge comes to the optimum: the local plan, handed over.

    python -m evaluation.local_plan --policy learned:mappo_small_pooling_1m --policy cbgabi --episodes 200

For each policy P it plays the held-out instances twice: P alone, and ``policies.local_plan`` for round 0 (each
agent bids on the tasks that the exact optima of teams drawn around its own start give it in at least half of the
draws), then P. Scores are divided by the exact optimum's mean, next to the oracle's hand-over of
``evaluation.handover`` (the optimum's own round 0, then P): the two rows bracket what a round 0 played without
hearing anyone can give. The local plan costs N × ``--samples`` exact solves per instance (about 5 s on
``train_small`` with 24 draws); it is solved once per instance and reused by every policy's row.
docs/learning.md ("What a first round can know") quotes this table.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from evaluation.episodes import skip_reason
from evaluation.handover import REFERENCES, Handover, markdown, played, reference_allocations
from evaluation.seeds import add_heldout_arguments, heldout_seeds
from policies import make_policy
from policies.local_plan import LocalPlanPolicy
from taskalloc_env.config import resolve_config
from taskalloc_env.errors import ConfigError, run_cli


def main(argv: Sequence[str] | None = None) -> str:
    parser = argparse.ArgumentParser(prog="python -m evaluation.local_plan", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenario", default="train_small", help="scenario name or YAML path (default train_small)")
    parser.add_argument("--policy", action="append", metavar="NAME",
                        help="a policy name (repeatable; default: learned:mappo_small_pooling_1m and cbgabi)")
    parser.add_argument("--samples", type=int, default=24, help="teams drawn per agent (default 24)")
    parser.add_argument("--reference", choices=sorted(REFERENCES), default="exact",
                        help="what solves the drawn teams and divides the scores: the exact optimum (default; "
                             "small instances only) or LNS, a lower bound on it at any size")
    add_heldout_arguments(parser)
    args = parser.parse_args(argv)
    seeds = heldout_seeds(args)
    if args.samples < 1:
        raise ConfigError(f"--samples: got {args.samples}; allowed: integers >= 1")
    reason = skip_reason(args.reference, resolve_config(args.scenario))
    if reason:
        raise ConfigError(f"--scenario {args.scenario}: {reason} (--reference lns plays at any size)")
    policies = args.policy or ["learned:mappo_small_pooling_1m", "cbgabi"]
    for name in policies:
        try:
            make_policy(name)
        except ValueError as exc:       # a CheckpointError is a ConfigError already
            raise ConfigError(f"--policy {name}: {exc}") from None
    planner = LocalPlanPolicy(args.samples, args.reference)      # one instance: its plans are reused by every row
    table = []
    for name in policies:
        table.append((name, played(make_policy(name), args.scenario, seeds)))
        table.append((f"{planner.name} for round 0, then {name}",
                      played(Handover(planner, make_policy(name), 1), args.scenario, seeds)))
    out = markdown(table, reference_allocations(args.scenario, seeds, args.reference), args.reference)
    print(f"{args.scenario}, seeds {seeds[0]}–{seeds[-1]}\n\n{out}")
    return out


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
