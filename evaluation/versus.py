"""Each run of a benchmarked method against a baseline on the same test seeds: ``taskalloc benchmark --versus``.

Per run and task: the run's mean score as a share of the baseline's mean on the same seeds, the two-sided paired
t-test p-value of the per-seed differences (thesis §5.3.1's paired design), and the seeds the run wins. The
instances are matched by task and seed, and their fingerprints must agree (the same instance was played).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from taskalloc.evaluation.stats import format_p, paired_t_pvalue
from taskalloc_env.errors import ConfigError
from taskalloc_env.suite import SUITE, TASKS

Episodes = dict[tuple[str, int], dict[str, str]]
ORDER = {t: k for k, t in enumerate(TASKS)}      # the suite's order


def read_runs(folder: Path) -> tuple[str, dict[int, Episodes]]:
    """A benchmark folder → (its method's label, per run the episodes by (task, seed))."""
    path = folder / "episodes.csv"
    if not path.is_file():
        raise ConfigError(f"--versus: {str(folder)!r} holds no episodes.csv")
    runs: dict[int, Episodes] = {}
    with path.open(encoding="utf-8", newline="") as handle:
        for row in csv.DictReader(handle):
            runs.setdefault(int(row["run"]), {})[row["task"], int(row["seed"])] = row
    summary = folder / "summary.json"
    label = folder.name
    if summary.is_file():
        label = json.loads(summary.read_text(encoding="utf-8")).get("policy", label)
    return label, runs


def versus_table(baseline: Path, folders: Sequence[Path]) -> str:
    """One markdown row per (method, run, task) the baseline also played."""
    base_label, base_runs = read_runs(baseline)
    if len(base_runs) != 1:
        raise ConfigError(f"--versus: the baseline {str(baseline)!r} must hold one run, it holds {len(base_runs)}")
    base = next(iter(base_runs.values()))
    lines = [f"| policy | run | task | episodes | % of {base_label} | paired p | wins |",
             "|---|---:|---|---:|---:|---:|---:|"]
    for folder in folders:
        label, runs = read_runs(folder)
        for run, episodes in sorted(runs.items()):
            tasks = dict.fromkeys(t for t, _ in episodes)
            for task_id in sorted(tasks, key=lambda t: ORDER.get(t, len(ORDER))):
                keys = [k for k in episodes if k[0] == task_id and k in base]
                if not keys:
                    continue
                for key in keys:
                    if episodes[key]["instance"] != base[key]["instance"]:
                        raise ConfigError(f"--versus: {task_id} seed {key[1]} is another instance in "
                                          f"{str(folder)!r} than in {str(baseline)!r}")
                a = np.array([float(episodes[k]["score"]) for k in keys])
                b = np.array([float(base[k]["score"]) for k in keys])
                name = task_id.split("/", 1)[-1].removesuffix(f"-{SUITE}")
                lines.append(f"| {label} | {run} | {name} | {len(keys)} | {100 * a.mean() / b.mean():.2f} | "
                             f"{format_p(paired_t_pvalue(a, b))} | {int((a > b).sum())}/{len(keys)} |")
    return "\n".join(lines) + "\n"
