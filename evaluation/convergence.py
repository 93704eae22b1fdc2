"""How often greedy CBBA/CBGA converges under each travel-cost option (the evidence behind ``distance_cost``).

    python -m evaluation.convergence [--seeds 50] [--max-rounds 100]

CBBA's convergence and conflict-freedom rest on diminishing marginal gains (DMG, Johnson §3.4.1 eq. (3.13);
thesis eq. (2.5)). The ``leg``
cost (γ × the detour an insertion adds) is not DMG: inserting a task next to j can shrink j's detour and raise its
bid, so bids can cycle. ``from_start`` (γ × the straight distance from the agent's start, the fuel penalty of the
public MIT CBBA Matlab code; the thesis says only that its Matlab implementation extends a CBBA implementation,
§3.3.1) keeps DMG. The table shows the share of
runs that converge within ``--max-rounds`` rounds on the thesis's test scenario (§3.3.2; 10 agents, 20 tasks).
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np

from policies import make_policy, rollout
from taskalloc_env import TaskAllocEnv
from taskalloc_env.errors import run_cli


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=50)
    parser.add_argument("--max-rounds", type=int, default=100)
    args = parser.parse_args(argv)
    policy = make_policy("cbga")
    print(f"{'distance_cost':14s} {'marginal_gain':14s} {'L_j':>4s} {'converged':>10s} {'rounds (conv.)':>15s}")
    for cost, gain, agents in itertools.product(("from_start", "leg"), ("rescore", "frozen"), (1, 2, 4)):
        env = TaskAllocEnv(distance_cost=cost, marginal_gain=gain, agents_per_task=agents,
                           max_rounds=args.max_rounds)
        runs = [rollout(env, policy, seed=s) for s in range(args.seeds)]
        done = [r for r in runs if r.converged]
        rounds = f"{np.mean([r.counters.rounds for r in done]):.1f}" if done else "-"
        print(f"{cost:14s} {gain:14s} {agents:4d} {len(done):5d}/{args.seeds:<4d} {rounds:>15s}")


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
