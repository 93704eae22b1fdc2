"""How often greedy CBGA converges under each travel-cost and bid option (the evidence behind the defaults).

    taskalloc convergence                                 # the defaults' rows, 1000 seeds each
    taskalloc convergence --seeds 200 --all --out docs/convergence.md

CBBA's convergence and conflict-freedom rest on diminishing marginal gains (DMG, Johnson §3.4.1 eq. (3.13);
thesis eq. (2.5)). The per-leg cost of thesis (3.9) (``distance_cost="leg"``: γ × the detour an insertion adds) is
not DMG, and neither are re-timed gains (``marginal_gain="rescore"``, (3.11)): inserting a task can raise the value
of another, and greedy bids can cycle. Warped bids (``bid_warping``: the shared bid is min(c_ij, the agent's earlier
bundle bids), so shared bids follow DMG; our construction, after Johnson §4.3's allusion to unpublished work
that allows such costs "as long as external bids follow DMG") restore convergence. Each row runs a policy on the
thesis's test scenario (§3.3.2; 10 agents, 20 tasks) at one L_j and reports the share of seeds that converge
before the round bound, the rounds they took, and the mean score.
"""

from __future__ import annotations

import argparse
import itertools
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from taskalloc.evaluation.episodes import Episode, default_jobs, run_episodes
from taskalloc.evaluation.report import markdown_table
from taskalloc_env import resolve_config
from taskalloc_env.errors import ConfigError, run_cli

DEFAULT_ROWS = [("leg", gain, True) for gain in ("rescore", "frozen")]
COST_ROWS = [(cost, gain, True) for cost, gain in itertools.product(("leg", "from_start"), ("rescore", "frozen"))]
ALL_ROWS = [(cost, gain, warp) for cost, gain, warp in itertools.product(("leg", "from_start"), ("rescore", "frozen"),
                                                                          (True, False))]


def table(rows: Sequence[tuple[str, str, bool]], policies: Sequence[str], levels: Sequence[int], seeds: int,
          jobs: int, progress: bool = True) -> str:
    """The markdown table: one line per (policy, distance_cost, marginal_gain, bid_warping, L_j)."""
    cells = {}
    episodes = []
    for policy, (cost, gain, warp), level in itertools.product(policies, rows, levels):
        cfg = resolve_config("default", distance_cost=cost, marginal_gain=gain, bid_warping=warp,
                             agents_per_task=level)
        key = (policy, cost, gain, warp, level)
        cells[key] = []
        episodes += [Episode(policy, cfg, seed, (("cell", key),)) for seed in range(seeds)]
    for row in run_episodes(episodes, jobs=jobs, progress=progress, desc="convergence"):
        cells[row["cell"]].append(row)
    body = []
    for (policy, cost, gain, warp, level), rows_ in cells.items():
        done = [r for r in rows_ if r["converged"]]
        rounds = f"{np.mean([r['rounds'] for r in done]):.1f}" if done else "–"
        body.append([policy, cost, gain, "yes" if warp else "no", level, f"{len(done)}/{len(rows_)}", rounds,
                     f"{np.mean([r['score'] for r in rows_]):.1f}"])
    header = ["policy", "distance_cost", "marginal_gain", "bid_warping", "L_j", "converged", "rounds (converged)",
              "score (mean)"]
    return markdown_table(header, body)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="taskalloc convergence", description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=1000, help="seeds per row (default 1000)")
    parser.add_argument("--all", action="store_true",
                        help="every combination of distance_cost, marginal_gain and bid_warping (default: the "
                             "defaults' leg + warping under both marginal-gain modes)")
    parser.add_argument("--costs", action="store_true",
                        help="both distance costs (leg, from_start) under both marginal-gain modes, with warping: "
                             "the score both ways (the rows without warping run to the round bound, so --all is slow)")
    parser.add_argument("--policies", default="cbga,cbgabi", help="comma-separated policies (default cbga,cbgabi)")
    parser.add_argument("--levels", default="1,2,4", help="comma-separated L_j values (default 1,2,4)")
    parser.add_argument("--jobs", type=int, default=default_jobs(), help="worker processes (default: every core)")
    parser.add_argument("--out", type=Path, help="also write the table (with its command) to this markdown file")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        raise ConfigError(f"--seeds: got {args.seeds}; allowed: an integer >= 1")
    levels = [int(v) for v in args.levels.split(",")]
    rows = ALL_ROWS if args.all else COST_ROWS if args.costs else DEFAULT_ROWS
    text = table(rows, args.policies.split(","), levels, args.seeds, args.jobs)
    print(text)
    if args.out:
        command = "taskalloc convergence " + " ".join(argv if argv is not None else [])
        args.out.write_text(f"<!-- written by `{command.strip()}` -->\n{text}")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
