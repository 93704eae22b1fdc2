"""A quick table: baselines, centralised solvers and any learned checkpoints on held-out seeds.

    taskalloc heldout                                   # the committed models, seeds 10000..10199
    taskalloc heldout --scenario default --episodes 20 --learned "mine=runs/x/model.json"

Rows: random, CBGA, CBGABI (scripted, decentralised), SGAMA (centralised greedy), LNS
(``taskalloc.policies.local_search``, a lower bound on the optimum), the exact optimum where it is tractable, and every
``--learned LABEL=PATH`` checkpoint (default: the committed models ``train_small``, ``mappo_small`` and
``mappo_small_pooling_1m``). A checkpoint that cannot be loaded is refused before any episode is played, never left out
of the table; one that loads but does not fit the scenario's size is skipped with its reason. The tables of
``docs/learning.md``, with several training seeds per configuration, come from ``taskalloc.evaluation.learning_report``.
Each policy runs in an environment built with its ``env_overrides``; seed s is the same instance for every row (the
instance is drawn at ``reset(seed=s)`` before any policy acts). Learned policies act greedily: the most likely kind of
action (pass, bid, quit or release), then its most likely action (``taskalloc.policies.learned.greedy_actions``).
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from taskalloc.evaluation.episodes import Episode, run_episode, skip_reason
from taskalloc.evaluation.seeds import add_heldout_arguments, heldout_seeds
from taskalloc.evaluation.stats import format_mean_sd, format_p, paired
from taskalloc.policies.registry import make_policy
from taskalloc_env.config import resolve_config
from taskalloc_env.errors import run_cli

# the committed models (models/): a row the default names is always there, never dropped for a missing file
DEFAULT_LEARNED = (
    ("SB3 PPO from scratch", "train_small"),
    ("MAPPO attention", "mappo_small"),
    ("MAPPO pooling, 1 M steps", "mappo_small_pooling_1m"),
)
SCRIPTED = (("random", "random"), ("CBGA", "cbga"), ("CBGABI", "cbgabi"))
CENTRALISED = (("SGAMA (centralised greedy)", "sgama"), ("LNS (centralised group search)", "lns"),
               ("exact optimum", "exact"))


def run_rows(scenario: str, seeds: Sequence[int], learned: Sequence[tuple[str, str]]) -> list[dict[str, Any]]:
    """One record per row: label, per-seed scores and mean figures, and the seconds it took.

    Each episode goes through ``taskalloc.evaluation.episodes.run_episode``, the experiment runner's paired
    evaluation."""
    cfg = resolve_config(scenario)
    for _, path in learned:     # a missing or broken checkpoint is an error, not a row silently left out
        make_policy(f"learned:{path}")
    solvers = [(label, name, "policy") for label, name in SCRIPTED]
    solvers += [(label, name, "solver") for label, name in CENTRALISED]
    solvers += [(label, f"learned:{path}", "policy") for label, path in learned]
    rows = []
    for label, solver, kind in solvers:
        t0 = time.perf_counter()
        reason = skip_reason(solver, cfg)
        try:
            if reason:
                raise ValueError(reason)
            episodes = [run_episode(Episode(solver, cfg, int(seed))) for seed in seeds]
        except ValueError as exc:       # the exact solver refuses large instances; a learned MLP other sizes
            print(f"{label}: skipped ({exc})", flush=True)
            continue
        rows.append({"label": label, "kind": kind, "seconds": round(time.perf_counter() - t0, 1),
                     "scores": [e["score"] for e in episodes],
                     **{m: float(np.mean([e[m] or 0 for e in episodes])) for m in ("valid_tasks", "rounds",
                                                                                    "messages")}})
        print(f"{label}: {np.mean(rows[-1]['scores']):.1f} ({rows[-1]['seconds']} s)", flush=True)
    return rows


def markdown(rows: Sequence[dict[str, Any]], seeds: Sequence[int]) -> str:
    """Mean ± sd score, % of CBGABI and of the optimum, the paired comparison with CBGABI, protocol figures."""
    by_label = {r["label"]: np.asarray(r["scores"]) for r in rows}
    ref = by_label["CBGABI"]
    opt = by_label["exact optimum"].mean() if "exact optimum" in by_label else float("nan")
    lines = [f"Held-out seeds {seeds[0]}–{seeds[-1]} ({len(seeds)} instances). Δ: paired mean difference to CBGABI "
             "with its 95 % t-interval; p: paired t-test; wins / ties: share of seeds above / equal to CBGABI.", "",
             "| policy | score (mean ± sd) | % of CBGABI | % of optimum | Δ vs CBGABI (95 % CI) | p | wins | ties "
             "| valid tasks | rounds | messages |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        s = by_label[r["label"]]
        pc = paired(s, ref)
        protocol = f"{r['rounds']:.2f} | {r['messages']:.1f}" if r["kind"] == "policy" else "– | –"
        of_opt = "–" if np.isnan(opt) else f"{100 * s.mean() / opt:.1f} %"
        lines.append(f"| {r['label']} | {format_mean_sd(s, 1)} | {100 * pc.ratio:.1f} % | {of_opt} "
                     f"| {pc.mean_diff:+.1f} [{pc.ci95[0]:+.1f}, {pc.ci95[1]:+.1f}] | {format_p(pc.p_t)} "
                     f"| {100 * pc.better:.0f} % | {100 * pc.tied:.0f} % | {r['valid_tasks']:.2f} | {protocol} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> str:
    parser = argparse.ArgumentParser(prog="taskalloc heldout", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenario", default="train_small", help="scenario name or YAML path (default train_small)")
    add_heldout_arguments(parser)
    parser.add_argument("--learned", action="append", metavar="LABEL=PATH",
                        help="a checkpoint row (repeatable); default: the committed models")
    parser.add_argument("--json", type=Path, help="also write per-seed scores here")
    args = parser.parse_args(argv)
    seeds = heldout_seeds(args)
    learned = [tuple(item.split("=", 1)) for item in args.learned] if args.learned else \
        list(DEFAULT_LEARNED)
    rows = run_rows(args.scenario, seeds, learned)
    table = markdown(rows, seeds)
    print(table)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"seeds": seeds, "rows": rows}, indent=1))
    return table


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
