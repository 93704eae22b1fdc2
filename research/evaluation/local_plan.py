"""How close a round 0 played from one agent's own knowledge comes to the optimum: the local plan, handed over.

    python -m research.evaluation.local_plan --policy learned:mappo_small_pooling_1m --policy cbgabi --episodes 200

For each policy P it plays the held-out instances twice: P alone, and ``research.policies.local_plan`` for round 0
(each agent bids on the tasks that the exact optima of teams drawn around its own start give it in at least half of the
draws), then P. Scores are divided by the exact optimum's mean; read them next to the oracle's hand-over of
``research.evaluation.handover`` (the optimum's own round 0, then P): the two bracket what a round 0 played without
hearing anyone can give. With ``--reference lns`` the drawn teams are solved by the group search
(``taskalloc.policies.local_search``) and scores are divided by its mean, at any size:

    python -m research.evaluation.local_plan --scenario default --reference lns --episodes 40

The local plan costs N × ``--samples`` solves per instance (about 5 s on ``train_small`` with 24 draws, about half
a minute on the default scenario with LNS); it is computed once per instance and reused by every policy's row.
docs/learning.md ("What a round 0 can know") quotes these tables.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from research.evaluation.handover import (
    add_table_arguments,
    checked_table_arguments,
    markdown,
    played,
    reference_allocations,
)
from research.policies.handover import Handover
from research.policies.local_plan import LocalPlanPolicy
from taskalloc.policies import make_policy
from taskalloc_env.errors import ConfigError, run_cli


def main(argv: Sequence[str] | None = None) -> str:
    parser = argparse.ArgumentParser(prog="python -m research.evaluation.local_plan", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=24, help="teams drawn per agent (default 24)")
    add_table_arguments(parser)
    args = parser.parse_args(argv)
    if args.samples < 1:
        raise ConfigError(f"--samples: got {args.samples}; allowed: integers >= 1")
    seeds, policies = checked_table_arguments(args)
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
