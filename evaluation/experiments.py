"""Experiment runner: the thesis's experiments (§3.3, §5.3) as YAML files, run on paired seeds, with reports.

    taskalloc experiments run configs/experiments/fig5_16_l4.yaml [--episodes N] [--jobs N] [--quick]
    taskalloc experiments run --all --overwrite   # every configs/experiments/*.yaml, rewrites results/
                                                             # and docs/results.md
    taskalloc experiments report --all --overwrite   # tables, plots and docs again from the saved CSVs
    taskalloc experiments list

Each experiment runs every series on the same seeds 0..N−1 at every sweep point (the paired design of thesis
§5.3.1) and writes to ``<out>/<name>/``: ``episodes.csv`` (one row per episode, non-converged ones included and
flagged), ``table.md`` (mean ± sd per cell, paired figures against the baseline: Δ, ratio, paired t-test and
Wilcoxon p-values, share of seeds won and tied; the published claims checked), one PNG per metric, a bar plot with
per-seed differences at each headline point, ``config.yaml`` (the experiment and every resolved environment config)
and ``run.json`` (package versions, commit, wall time). A full run also rewrites the experiment's block in
``docs/results.md`` (between ``<!-- results:NAME:start/end -->`` markers; the text around the blocks is kept).
``--quick`` runs 2 seeds at ≤ 3 sweep points into ``results/tmp/quick`` and leaves the docs alone. ``run`` refuses
(one line, exit status 2) an experiment folder that already holds files, or a results page that already holds the
experiment's block, unless ``--overwrite`` is given; ``report`` rewrites them by design.

The experiment files and their keys: ``experiment_files``; the tables, figures and results-page blocks:
``experiment_reports``.
"""

from __future__ import annotations

import argparse
import json
import platform
import resource
import subprocess
import sys
import time
import warnings
from collections.abc import Mapping, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

import yaml

from taskalloc.evaluation.distributed import BACKENDS, require_ray
from taskalloc.evaluation.episodes import Episode, check_pairing, default_jobs, run_episodes, skip_reason
from taskalloc.evaluation.experiment_files import Experiment, Point, load_experiment
from taskalloc.evaluation.experiment_reports import check_docs, suite_block, update_docs, write_reports
from taskalloc.evaluation.report import read_csv, refuse_existing, write_csv
from taskalloc_env import resources
from taskalloc_env.config import to_mapping
from taskalloc_env.errors import ConfigError, run_cli

ROOT = Path(__file__).resolve().parent.parent   # the checkout (for the git commit of a run), if this is one
RESULTS, DOCS = Path("results"), Path("docs") / "results.md"     # relative to where the command runs
PACKAGES = ("taskalloc", "numpy", "scipy", "pettingzoo", "gymnasium", "matplotlib", "pyyaml", "tqdm")


# -- running -----------------------------------------------------------------------------------------------------------
def plan(exp: Experiment, points: Sequence[Point], episodes: int) -> tuple[list[Episode], list[str]]:
    """Every episode of the experiment (seeds innermost), and notes on cells skipped as not applicable."""
    runs, skipped = [], []
    for point in points:
        for s in exp.series:
            cfg = exp.config(point, s)
            reason = skip_reason(s.solver, cfg)
            if reason:
                skipped.append(f"{s.label} at {exp.xlabel} = {point.label}: {reason}")
                continue
            labels = (("experiment", exp.name), ("point", point.label), ("series", s.label))
            runs += [Episode(s.solver, cfg, seed, labels) for seed in range(episodes)]
    return runs, skipped


def run_experiment(exp: Experiment, out: Path, jobs: int, episodes: int | None = None, quick: bool = False,
                   progress: bool = True, docs: Path | None = None, backend: str = "local") -> Path:
    """Run ``exp`` and write every output under ``out / exp.name``; returns that directory."""
    points = exp.quick_points if quick else exp.points
    n = episodes or (exp.quick_episodes if quick else exp.episodes)
    runs, skipped = plan(exp, points, n)
    started, cpu = time.perf_counter(), _cpu_seconds()
    rows = run_episodes(runs, jobs=jobs, progress=progress, desc=exp.name, backend=backend)
    wall, cpu = time.perf_counter() - started, _cpu_seconds() - cpu
    broken = check_pairing([r for r in rows if _same_generator(exp, r)], ["point"])
    if broken:
        raise RuntimeError(f"{exp.name}: paired seeds gave different instances: {broken[:3]}")
    target = out / exp.name
    target.mkdir(parents=True, exist_ok=True)
    write_csv(target / "episodes.csv", rows)
    (target / "config.yaml").write_text(yaml.safe_dump(_resolved(exp, points), sort_keys=False, allow_unicode=True))
    info = {"experiment": exp.name, "episodes_per_cell": n, "points": [p.label for p in points], "jobs": jobs,
            "backend": backend,
            "quick": quick, "wall_seconds": round(wall, 1), "cpu_seconds": round(cpu, 1),
            "episodes_total": len(rows),
            "command": " ".join(["taskalloc experiments", *sys.argv[1:]]) if sys.argv else "",
            "skipped": skipped, **environment_info()}
    (target / "run.json").write_text(json.dumps(info, indent=2) + "\n")
    write_reports(exp, rows, target, points, docs=docs)
    return target


def _cpu_seconds() -> float:
    """CPU time of this process and of its finished worker processes (user + system)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _same_generator(exp: Experiment, row: Mapping[str, Any]) -> bool:
    """Rows whose instances must match seed by seed: series without config overrides of their own."""
    return not next(s for s in exp.series if s.label == row["series"]).overrides


def _resolved(exp: Experiment, points: Sequence[Point]) -> dict[str, Any]:
    cells = {f"{p.label} | {s.label}": {"solver": s.solver, "config": to_mapping(exp.config(p, s))}
             for p in points for s in exp.series}
    return {"experiment": exp.raw, "resolved": cells}


def environment_info() -> dict[str, Any]:
    """Python, platform, package versions and the git commit (with a dirty flag) the results came from."""
    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                                check=True).stdout.strip()
        dirty = bool(subprocess.run(["git", "status", "--porcelain"], cwd=ROOT, capture_output=True,
                                    text=True).stdout.strip())
    except (OSError, subprocess.CalledProcessError):
        commit, dirty = None, None
    return {"python": platform.python_version(), "platform": platform.platform(), "packages": versions,
            "git_commit": commit, "git_dirty": dirty}


def report_experiment(exp: Experiment, out: Path, docs: Path | None) -> None:
    """Tables, plots and docs again from ``<out>/<name>/episodes.csv`` (no episodes are run)."""
    target = out / exp.name
    rows = read_csv(target / "episodes.csv")
    labels = {str(r["point"]) for r in rows}
    write_reports(exp, rows, target, [p for p in exp.points if p.label in labels], docs=docs)


# -- command line ------------------------------------------------------------------------------------------------------
def experiment_paths(paths: Sequence[str], every: bool) -> list[str]:
    if every:
        return resources.names("experiments")
    if not paths:
        raise ConfigError("name experiments (taskalloc experiments list) or files, or pass --all")
    return list(paths)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="taskalloc experiments", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run experiments and write their results")
    report = sub.add_parser("report", help="rewrite tables, plots and docs from saved episodes.csv files")
    sub.add_parser("list", help="list the experiment files")
    for p in (run, report):
        p.add_argument("paths", nargs="*", metavar="NAME_OR_FILE",
                       help="experiment names (see `list`) or experiment YAML files")
        p.add_argument("--all", action="store_true", help="every experiment of configs/experiments")
        p.add_argument("--out", type=Path, default=None,
                       help=f"results folder (default {RESULTS}/; {RESULTS}/tmp/quick with run --quick)")
        p.add_argument("--docs", type=Path, default=None,
                       help=f"results page whose experiment blocks to rewrite (default {DOCS} when it exists; "
                            "never with run --quick unless given)")
        p.add_argument("--no-docs", action="store_true", help="leave the results page alone")
        p.add_argument("--overwrite", action="store_true",
                       help="replace existing results (an experiment folder that holds files, or the experiment's "
                            "block on the results page); without it they are refused")
    run.add_argument("--episodes", type=int, default=None, help="seeds per cell (default: the file's, 100)")
    run.add_argument("--jobs", type=int, default=default_jobs(), help="worker processes (default: all cores)")
    run.add_argument("--quick", action="store_true", help="2 seeds at <= 3 points, into results/tmp/quick")
    run.add_argument("--backend", choices=BACKENDS, default="local",
                     help="local: --jobs processes; ray: Ray tasks on a local Ray instance or the cluster RAY_ADDRESS "
                          "names (pip install taskalloc[ray]); the same tables either way")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if args.command == "list":
        for name in resources.names("experiments"):
            with warnings.catch_warnings():     # a listing, not a run: a sweep point's caveats belong to the run
                warnings.simplefilter("ignore")
                title = load_experiment(name).title
            print(f"{name:<26} {title}")
        return 0
    quick = args.command == "run" and args.quick
    out = args.out or (RESULTS / "tmp" / "quick" if quick else RESULTS)
    docs = args.docs or (None if quick or not DOCS.exists() else DOCS)
    if args.no_docs:
        docs = None
    experiments = [load_experiment(p) for p in experiment_paths(args.paths, args.all)]
    if args.command == "run" and args.backend == "ray":
        require_ray()
    for exp in experiments:
        if args.command == "run":
            refuse_existing(out / exp.name, args.overwrite, "output folder")
        if docs is not None:
            check_docs(docs, exp.name, args.overwrite)
    if docs is not None and args.all:
        check_docs(docs, "suite", args.overwrite)
    started = time.perf_counter()
    for exp in experiments:
        if args.command == "report":
            report_experiment(exp, out, docs)
            continue
        t0 = time.perf_counter()
        target = run_experiment(exp, out, args.jobs, args.episodes, quick, not args.no_progress, docs, args.backend)
        print(f"{exp.name}: {time.perf_counter() - t0:.1f} s -> {target.relative_to(out.parent)}/table.md")
    print(f"total {time.perf_counter() - started:.1f} s")
    if docs is not None and args.all:
        update_docs(docs, "suite", "Run summary", suite_block(experiments, out, docs))
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
