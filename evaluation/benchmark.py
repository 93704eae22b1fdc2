"""``taskalloc benchmark``: one evaluation protocol for any policy on the task suite (docs/benchmark.md).

``taskalloc benchmark --suite v0 --policy P --out DIR [--tasks …] [--episodes N]`` plays P on every task's test
seeds and writes ``DIR/episodes.csv`` (raw episodes), ``DIR/summary.json``, ``DIR/summary.md`` and
``DIR/marl_eval.json``. P is a baseline name (``cbgabi``), ``learned:<name or path>``, or ``pkg.module:Object``
(anything with ``act(observations, infos)`` and optional ``start(env, seed)``, or a function of the observations;
``taskalloc.policies.plugins``); ``--policy`` given several times names runs of one method (e.g. training seeds),
whose spread the intervals then include. Scores are normalised against the committed reference
(``taskalloc.evaluation.suite_reference``) on the same seeds (``taskalloc.evaluation.benchmark_stats``).

Bad input, checked before any episode: an unknown task id lists the suite's ids; a policy that does not resolve is
one line and exit 2; an existing ``--out`` needs ``--overwrite``. An action outside the mask is counted per task
(``--invalid-action noop``, the default) or stops the run naming the agent and action (``raise``, exit 1). A task
whose environment the policy refuses (``ValueError`` from ``start``: a checkpoint trained on other features) is
marked ``not_applicable`` with the reason, left out of the aggregate, and named on stderr.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from taskalloc.evaluation import benchmark_stats as bstats
from taskalloc.evaluation.episodes import default_jobs, solver_name
from taskalloc.evaluation.suite_episodes import ROW_FIELDS, play_task
from taskalloc.evaluation.suite_reference import load_reference, means, write_reference
from taskalloc.evaluation.training_cost import training_cost
from taskalloc.evaluation.versus import versus_table
from taskalloc_env.errors import ConfigError, InvalidActionError
from taskalloc_env.suite import SUITE, TASKS, cards, task

FILES = ("episodes.csv", "summary.json", "summary.md", "marl_eval.json")


def check_policy(name: str) -> str:
    """The policy's display name; a name or path that does not resolve is a ``ConfigError`` (one line)."""
    try:
        return solver_name(name)
    except ConfigError:
        raise
    except (ValueError, TypeError, ImportError, OSError) as exc:
        raise ConfigError(f"--policy {name!r}: {exc}") from None


def check_out(out: Path, overwrite: bool) -> None:
    """Refuse an existing ``--out`` folder unless ``overwrite``; a file there is refused either way."""
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {str(out)!r} is a file, not a folder")
    if out.exists() and any(out.iterdir()) and not overwrite:
        raise ConfigError(f"--out {str(out)!r} exists; pass --overwrite to replace its files")


def task_seeds(task_id: str, episodes: int | None) -> list[int]:
    """The first ``episodes`` test seeds of the task (all of them without a cap)."""
    seeds = list(task(task_id).test_seeds)
    return seeds if episodes is None else seeds[:episodes]


def run(policies: Sequence[str], task_ids: Sequence[str], episodes: int | None = None, invalid_action: str = "noop",
        jobs: int = 1, label: str | None = None) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Play every run (``policies``) on every task; the summary and the episode rows."""
    reference = load_reference(SUITE)["tasks"]
    missing = [t for t in task_ids if t not in reference]
    if missing:
        raise ConfigError(f"the suite's reference has no entry for {missing}; run taskalloc benchmark "
                          "--write-reference --tasks ...")
    names = [check_policy(p) for p in policies]
    label = label or (names[0] if len(set(names)) == 1 else " + ".join(names))
    rows: list[dict[str, Any]] = []
    tasks: dict[str, Any] = {}
    scores: dict[str, np.ndarray] = {}
    normalised: dict[str, np.ndarray] = {}
    for task_id in task_ids:
        seeds = task_seeds(task_id, episodes)
        ref = means(reference[task_id], seeds)
        runs = []
        try:
            for policy in policies:
                runs.append(play_task(policy, task_id, seeds, invalid_action, jobs))
        except InvalidActionError:
            raise
        except ValueError as exc:           # the policy refuses the task's env (a checkpoint of other features)
            tasks[task_id] = {"seeds": seeds, "episodes": 0, "not_applicable": str(exc).splitlines()[0]}
            print(f"benchmark: {task_id} skipped: {tasks[task_id]['not_applicable']}", file=sys.stderr)
            continue
        for k, task_rows in enumerate(runs):
            norm = bstats.normalise([r["score"] for r in task_rows], ref)
            for row, value in zip(task_rows, norm):
                rows.append({"run": k, **row, "normalised": float(value)})
        scores[task_id] = np.array([[r["score"] for r in run_rows] for run_rows in runs])
        normalised[task_id] = bstats.normalise(scores[task_id], ref)
        tasks[task_id] = {"seeds": seeds, "episodes": len(seeds) * len(policies), "runs": len(policies),
                          **bstats.task_figures(scores[task_id], ref),
                          "invalid_actions": int(sum(r["invalid_actions"] for run_rows in runs for r in run_rows)),
                          "normaliser": ref["normaliser"], "best_known": ref["best_known"],
                          "random_score": ref["random"], "normaliser_score": ref["normaliser_score"],
                          "normaliser_gap": ref["normaliser_score"] - ref["random"],
                          "best_known_score": ref["best_known_score"]}
    if not normalised:
        raise ConfigError(f"{label} applies to none of the tasks {list(task_ids)}")
    summary = {"suite": SUITE, "policy": label, "runs": list(policies), "invalid_action": invalid_action,
               "tasks": tasks, "aggregate": bstats.aggregate(bstats.aggregate_matrix(normalised))}
    costs = [training_cost(p) for p in policies]
    if any(costs):
        summary["training"] = costs
    summary["marl_eval"] = bstats.marl_eval_json(label, scores, normalised)
    return summary, rows


def markdown(summary: dict[str, Any]) -> str:
    """The summary as a markdown table (one row per task, then the aggregate)."""
    head = ["task", "episodes", "score", "normalised", "95 % CI", "share of best known", "normaliser", "invalid"]
    lines = [f"Suite {summary['suite']}, policy {summary['policy']}", "", "| " + " | ".join(head) + " |",
             "|" + "---|" * len(head)]
    for task_id, t in summary["tasks"].items():
        if "not_applicable" in t:
            lines.append(f"| {task_id} | 0 | not applicable: {t['not_applicable'][:100]} |" + " |" * 5)
            continue
        share = "–" if t["best_known_share"] is None else f"{t['best_known_share']:.3f} ({t['best_known']})"
        lines.append(f"| {task_id} | {t['episodes']} | {t['score']:.1f} | {t['normalised']:.3f} | "
                     f"[{t['ci95'][0]:.3f}, {t['ci95'][1]:.3f}] | {share} | {t['normaliser']} | "
                     f"{t['invalid_actions']} |")
    agg = summary["aggregate"]
    lines += ["", f"Aggregate over {agg['tasks']} tasks (rliable, stratified bootstrap, {agg['reps']} reps): "
              f"IQM {agg['iqm']:.3f} [{agg['iqm_ci95'][0]:.3f}, {agg['iqm_ci95'][1]:.3f}], "
              f"mean {agg['mean']:.3f} [{agg['mean_ci95'][0]:.3f}, {agg['mean_ci95'][1]:.3f}]"]
    return "\n".join(lines) + "\n"


def reference_table(task_ids: Sequence[str]) -> str:
    """The reference's mean scores per task: random, the normaliser, the best known, and the normalising gap."""
    reference = load_reference(SUITE)["tasks"]
    lines = ["| task | seeds | random | normaliser | best known | (normaliser − random) / best known |",
             "|---|---:|---:|---:|---:|---:|"]
    for task_id in task_ids:
        if task_id not in reference:
            continue
        ref = means(reference[task_id], reference[task_id]["seeds"])
        gap = (ref["normaliser_score"] - ref["random"]) / ref["best_known_score"]
        lines.append(f"| {task_id} | {len(reference[task_id]['seeds'])} | {ref['random']:.1f} | "
                     f"{ref['normaliser_score']:.1f} ({ref['normaliser']}) | {ref['best_known_score']:.1f} "
                     f"({ref['best_known']}) | {gap:.3f} |")
    return "\n".join(lines) + "\n"


def leaderboard(folders: Sequence[Path]) -> str:
    """One row per benchmarked policy (its ``summary.json``), one column per task: normalised scores, then the IQM."""
    summaries = []
    for folder in folders:
        path = folder / "summary.json"
        if not path.is_file():
            raise ConfigError(f"--leaderboard: {str(folder)!r} holds no summary.json")
        summaries.append(json.loads(path.read_text(encoding="utf-8")))
    seen = {t for s in summaries for t in s["tasks"]}
    task_ids = [t for t in TASKS if t in seen] + sorted(seen - set(TASKS))        # the suite's order
    names = [t.split("/", 1)[-1].removesuffix(f"-{SUITE}") for t in task_ids]
    ran = {id(s): sum("normalised" in s["tasks"].get(t, {}) for t in task_ids) for s in summaries}
    ranked = sorted(summaries, key=lambda s: (-ran[id(s)], -s["aggregate"]["iqm"]))    # whole-suite rows first
    tables = []
    for figure, first in (("normalised", "IQM [95 % CI]"), ("best_known_share", "mean (tasks run)")):
        lines = [f"| policy | {first} | " + " | ".join(names) + " |", "|---|---|" + "---:|" * len(names)]
        for s in ranked:
            values = [s["tasks"].get(t, {}).get(figure) for t in task_ids]
            agg = s["aggregate"]
            lead = (f"{agg['iqm']:.2f} [{agg['iqm_ci95'][0]:.2f}, {agg['iqm_ci95'][1]:.2f}]" if figure == "normalised"
                    else f"{np.mean([v for v in values if v is not None]):.3f}")
            if ran[id(s)] < len(task_ids):
                lead += f" ({ran[id(s)]} task{'s' if ran[id(s)] > 1 else ''})"
            cells = ["–" if v is None else f"{v:.{2 if figure == 'normalised' else 3}f}" for v in values]
            lines.append(f"| {s['policy']} | {lead} | " + " | ".join(cells) + " |")
        tables.append("\n".join(lines))
    text = ("Normalised score (random 0, normaliser 1):\n\n" + tables[0]
            + "\n\nShare of the best known (exact optimum on Small, LNS elsewhere):\n\n" + tables[1] + "\n")
    trained = [s for s in ranked if s.get("training")]
    if trained:
        text += ("\nLearned rows across their training runs: the cost of one run (mean over the runs, from each "
                 "checkpoint's summary.yaml) and, per task, the normalised score's mean with its 95 % t-interval over "
                 "the runs:\n\n" + _training_table(trained, task_ids, names) + "\n")
    return text


def _training_table(summaries: Sequence[dict[str, Any]], task_ids: Sequence[str], names: Sequence[str]) -> str:
    """One row per learned method: runs, agent steps, CPU and wall minutes per run, then mean [lo, hi] per task."""
    lines = ["| policy | runs | agent steps per run | CPU min per run (wall) | " + " | ".join(names) + " |",
             "|---|---:|---:|---:|" + "---:|" * len(names)]
    for s in summaries:
        costs = [c for c in s["training"] if c]
        steps = sorted({c["agent_steps"] for c in costs if c.get("agent_steps") is not None})
        cpus = [c["cpu_seconds"] / 60 for c in costs if c.get("cpu_seconds") is not None]
        walls = [c["wall_seconds"] / 60 for c in costs if c.get("wall_seconds") is not None]
        cells = []
        for t in task_ids:
            figures = s["tasks"].get(t, {})
            runs = figures.get("ci95_runs")
            cells.append("–" if "normalised" not in figures else f"{figures['normalised']:.2f}" if runs is None
                         else f"{figures['normalised']:.2f} [{runs[0]:.2f}, {runs[1]:.2f}]")
        step_text = ", ".join(f"{v:,}" for v in steps) or "–"
        cost_text = (f"{np.mean(cpus):.1f}" if cpus else "–") + (f" ({np.mean(walls):.1f})" if walls else "")
        lines.append(f"| {s['policy']} | {len(s['runs'])} | {step_text} | {cost_text} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write(out: Path, summary: dict[str, Any], rows: Sequence[dict[str, Any]]) -> None:
    """The four files of ``FILES`` in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    marl_eval = summary.pop("marl_eval")
    with (out / "episodes.csv").open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=["run", *ROW_FIELDS, "normalised"])
        writer.writeheader()
        writer.writerows(rows)
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    (out / "summary.md").write_text(markdown(summary), encoding="utf-8")
    (out / "marl_eval.json").write_text(json.dumps(marl_eval) + "\n", encoding="utf-8")


def parse_tasks(values: Sequence[str] | None) -> list[str]:
    """``--tasks``: ids (``taskalloc/Small-v0``) or short names (``Small``), comma- or space-separated."""
    if not values:
        return list(TASKS)
    ids = []
    for value in (v for item in values for v in item.split(",") if v):
        full = value if "/" in value else f"taskalloc/{value}-{SUITE}"
        ids.append(task(full).id)
    return ids


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="taskalloc benchmark", description=__doc__.split("\n\n")[0])
    p.add_argument("--suite", default=SUITE, help=f"the task suite (only {SUITE!r} exists)")
    p.add_argument("--policy", dest="policies", action="append", default=[], metavar="P",
                   help="baseline name, learned:<name or path>, or pkg.module:Object; repeat for runs of one method")
    p.add_argument("--name", default=None, help="the method's label in the summary (default: the policy's name)")
    p.add_argument("--out", type=Path, help="folder for episodes.csv, summary.json, summary.md, marl_eval.json")
    p.add_argument("--overwrite", action="store_true", help="replace the files of an existing --out folder")
    p.add_argument("--tasks", nargs="+", default=None, help="task ids or names (default: the whole suite)")
    p.add_argument("--episodes", type=int, default=None, help="at most N test seeds per task (default: all)")
    p.add_argument("--invalid-action", choices=("noop", "raise"), default="noop",
                   help="noop: count actions outside the mask (as passes); raise: stop at the first, naming it")
    p.add_argument("--jobs", type=int, default=1, help=f"worker processes (this machine: {default_jobs()})")
    p.add_argument("--list", action="store_true", help="list the suite's task ids and exit")
    p.add_argument("--cards", action="store_true", help="print the suite's task cards (markdown) and exit")
    p.add_argument("--reference-table", action="store_true",
                   help="print the committed reference's mean scores per task (markdown) and exit")
    p.add_argument("--leaderboard", nargs="+", type=Path, metavar="DIR",
                   help="print one markdown table of the normalised scores in these --out folders and exit")
    p.add_argument("--versus", nargs="+", type=Path, metavar=("BASELINE", "DIR"),
                   help="print each run of these --out folders against the first folder's run, task by task "
                        "(share of its score, paired p, wins on the same seeds) and exit")
    p.add_argument("--write-reference", action="store_true",
                   help="recompute configs/suites/v0/reference.json for --tasks (random, normaliser, best known)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = parser().parse_args(argv)
    if args.suite != SUITE:
        raise ConfigError(f"--suite {args.suite!r}: unknown suite; known: {SUITE}")
    task_ids = parse_tasks(args.tasks)
    if args.list:
        print("\n".join(task_ids))
        return 0
    if args.cards:
        print(cards(), end="")
        return 0
    if args.reference_table:
        print(reference_table(task_ids), end="")
        return 0
    if args.leaderboard:
        print(leaderboard(args.leaderboard), end="")
        return 0
    if args.versus:
        if len(args.versus) < 2:
            raise ConfigError("--versus BASELINE DIR [DIR ...]: a baseline folder and at least one folder to compare")
        print(versus_table(args.versus[0], args.versus[1:]), end="")
        return 0
    if args.episodes is not None and args.episodes < 1:
        raise ConfigError(f"--episodes: got {args.episodes}; allowed: an integer >= 1")
    if args.jobs < 1:
        raise ConfigError(f"--jobs: got {args.jobs}; allowed: an integer >= 1")
    if args.write_reference:
        print(write_reference(task_ids, args.jobs))
        return 0
    if not args.policies or args.out is None:
        raise ConfigError("benchmark needs --policy P and --out DIR (or --list, --write-reference)")
    check_out(args.out, args.overwrite)
    try:
        summary, rows = run(args.policies, task_ids, args.episodes, args.invalid_action, args.jobs, args.name)
    except InvalidActionError as exc:
        print(f"error: invalid action (--invalid-action raise): {exc}", file=sys.stderr)
        return 1
    if args.out.exists() and args.overwrite:
        for name in FILES:
            (args.out / name).unlink(missing_ok=True)
    write(args.out, summary, rows)
    print(markdown(summary), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
