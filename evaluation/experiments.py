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

Experiment YAML keys: ``name``, ``title``, ``source``, ``scenario`` (scenario name or path), ``overrides`` (config
fields), ``sweep`` (``{field, values, label}``, ``{points: [mapping…], x, label}``, a point's ``label`` key naming
it, or ``{grid: {field: values, field: values}, label}``, every combination, labelled ``a × b``), ``series`` (solver
names or ``{solver, label, overrides}``), ``baseline`` (a series label), ``metrics``, ``episodes``, ``headline``
(points to tabulate and bar-plot in the docs; the paired table there also shows the comm-step metrics listed in
``metrics``, under both stopping rules), ``published`` (markdown), ``checks`` (``{claim, a, b,
test: greater|less|same|ratio_above|ratio_below, metric, at, alpha, ratio}``), ``quick`` (``{points: [...],
episodes}``), ``marks`` (``[{metric, share, label}]``: a vertical line in every sweep plot at the first point where at
least ``share`` of the episodes have the yes/no ``metric``, e.g. where the network becomes connected, thesis Figs
4.6–4.7), ``reference`` (``{point, metrics}``: every series at every point paired against the same series at the
reference point on the same seeds — Δ with its 95 % interval, ratio, p-values — with a plot of the differences per
metric, e.g. each message-loss rate against perfect links), ``heatmap`` (with a two-field grid: ``{baseline, series:
[...], difference: [a, b], metric}``, the percent change of each series' mean over the baseline's per grid cell and
the difference of two such maps, as tables and heat-map PNGs; the docs then show these maps instead of the per-point
tables, and no sweep plots are drawn, so ``marks`` cannot go with it).
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import os
import platform
import re
import resource
import subprocess
import sys
import time
import warnings
from collections.abc import Mapping, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from taskalloc.evaluation.distributed import BACKENDS, require_ray
from taskalloc.evaluation.episodes import Episode, check_pairing, default_jobs, run_episodes, skip_reason, solver_name
from taskalloc.evaluation.report import (
    METRIC_DIGITS,
    METRIC_LABELS,
    PAIRED_HEADER,
    SHARE_METRICS,
    bar_and_differences,
    cell_text,
    compare_cells,
    heatmap_plot,
    markdown_table,
    not_converged,
    paired_columns,
    read_csv,
    reference_plot,
    refuse_existing,
    sweep_plot,
    values,
    write_csv,
)
from taskalloc.evaluation.stats import PairedComparison, format_p
from taskalloc_env import TaskAllocConfig, resolve_config, resources
from taskalloc_env.config import read_yaml, to_mapping
from taskalloc_env.errors import ConfigError, run_cli

ROOT = Path(__file__).resolve().parent.parent   # the checkout (for the git commit of a run), if this is one
RESULTS, DOCS = Path("results"), Path("docs") / "results.md"     # relative to where the command runs
MAX_DOCS_BYTES = 16 << 20       # the results page is about 100 kB
KEYS = {"name", "title", "source", "scenario", "overrides", "sweep", "series", "baseline", "metrics", "episodes",
        "headline", "published", "checks", "quick", "marks", "reference", "heatmap"}
COMM_METRICS = ("comm_steps", "comm_steps_to_agreement")     # one message per agent, to the end / to agreement
COMM_HEADER = {"comm_steps": "comm steps (end)", "comm_steps_to_agreement": "comm steps (agreement)"}
TESTS = ("greater", "less", "same", "ratio_above", "ratio_below")
PACKAGES = ("taskalloc", "numpy", "scipy", "pettingzoo", "gymnasium", "matplotlib", "pyyaml", "tqdm")


@dataclasses.dataclass(frozen=True)
class Series:
    """One line of an experiment: a solver, a label, and config overrides of its own (e.g. L_j = 1 for CBBA)."""

    label: str
    solver: str
    overrides: Mapping[str, Any]


@dataclasses.dataclass(frozen=True)
class Check:
    """A published claim tested on our data: ``a`` against ``b`` (series labels) at the points ``at``."""

    claim: str
    a: str
    b: str
    test: str
    metric: str = "score"
    at: tuple[Mapping[str, Any], ...] = ()      # empty: every point
    alpha: float = 0.01
    ratio: float = 1.0


@dataclasses.dataclass(frozen=True)
class Point:
    """A sweep point: its label, its x value (for plots) and the config overrides it sets."""

    label: str
    x: Any
    overrides: Mapping[str, Any]


@dataclasses.dataclass(frozen=True)
class Mark:
    """A vertical line in the sweep plots: the first point at which ``share`` of the episodes have ``metric``."""

    metric: str
    share: float
    label: str


@dataclasses.dataclass(frozen=True)
class Reference:
    """Pair every series at every point with the same series at ``point`` (same seeds), for ``metrics``."""

    point: Point
    metrics: tuple[str, ...]


@dataclasses.dataclass(frozen=True)
class Heatmap:
    """Percent change over ``baseline`` per cell of a two-field grid (``rows`` × ``columns``), and one difference."""

    rows: str
    columns: str
    baseline: str
    series: tuple[str, ...]
    difference: tuple[str, str] | None = None
    metric: str = "score"


@dataclasses.dataclass
class Experiment:
    """One experiment file, parsed and validated."""

    name: str
    title: str
    source: str
    scenario: str
    overrides: dict[str, Any]
    xlabel: str
    points: list[Point]
    series: list[Series]
    baseline: str | None
    metrics: list[str]
    episodes: int
    headline: list[Point]
    published: str
    checks: list[Check]
    quick_points: list[Point]
    quick_episodes: int
    raw: dict[str, Any]
    marks: list[Mark] = dataclasses.field(default_factory=list)
    reference: Reference | None = None
    heatmap: Heatmap | None = None

    def config(self, point: Point, series: Series) -> TaskAllocConfig:
        """The environment config of one cell: scenario < experiment overrides < point < series."""
        clash = set(point.overrides) & set(series.overrides)
        if clash:
            raise ValueError(f"{self.name}: series {series.label!r} and point {point.label!r} both set {sorted(clash)}")
        return resolve_config(self.scenario, **self.overrides, **point.overrides, **series.overrides)


SWEEP_KEYS = {"field", "values", "points", "x", "grid", "label"}


def _points(sweep: Mapping[str, Any] | None) -> tuple[list[Point], str]:
    if not sweep:
        return [Point("all", "all", {})], ""
    if not isinstance(sweep, Mapping) or set(sweep) - SWEEP_KEYS or not {"field", "points", "grid"} & set(sweep):
        raise ConfigError(f"sweep is {{field, values, label}}, {{points, x, label}} or {{grid, label}}, got {sweep!r}")
    for key in ("values", "points"):
        needed = key in sweep or (key == "values" and "field" in sweep)
        if needed and (not isinstance(sweep.get(key), list) or not sweep[key]):
            raise ConfigError(f"sweep {key} must be a non-empty list, got {sweep.get(key)!r}")
    if "grid" in sweep and (not isinstance(sweep["grid"], Mapping)
                            or not all(isinstance(v, list) and v for v in sweep["grid"].values())):
        raise ConfigError(f"sweep grid must map fields to non-empty lists of values, got {sweep['grid']!r}")
    if "grid" in sweep:
        fields = list(sweep["grid"])
        combos = itertools.product(*(sweep["grid"][f] for f in fields))
        points = [Point(" × ".join(_label(v) for v in combo), " × ".join(_label(v) for v in combo),
                        dict(zip(fields, combo))) for combo in combos]
        return points, sweep.get("label", " × ".join(fields))
    if "field" in sweep:
        field = sweep["field"]
        points = [Point(_label(v), v, {field: v}) for v in sweep["values"]]
        return points, sweep.get("label", field)
    points = []
    for entry in sweep["points"]:
        entry = dict(entry)
        label = str(entry.pop("label", None) or ", ".join(f"{k}={_label(v)}" for k, v in entry.items()))
        x = entry.get(sweep["x"], label) if "x" in sweep else label
        points.append(Point(label, x, entry))
    return points, sweep.get("label", sweep.get("x", "point"))


def _label(value: Any) -> str:
    return "/".join(map(str, value)) if isinstance(value, (list, tuple)) else str(value)


def _select(points: list[Point], wanted: Sequence[Any], where: str) -> list[Point]:
    """Points matching ``wanted`` entries: a mapping of config values, or a point label."""
    chosen = []
    for want in wanted:
        hits = [p for p in points if _matches(p, want)]
        if not hits:
            raise ValueError(f"{where}: {want!r} matches no sweep point ({[p.label for p in points]})")
        chosen += [p for p in hits if p not in chosen]
    return chosen


def _matches(point: Point, want: Any) -> bool:
    if isinstance(want, Mapping):
        return all(point.overrides.get(k) == v for k, v in want.items())
    return point.label == str(want)


def experiment_source(name_or_path: str | Path) -> Path | Any:
    """An experiment name (a file of ``configs/experiments``) or a path to a YAML file."""
    if isinstance(name_or_path, str) and resources.is_name(name_or_path):
        return resources.named("experiments", name_or_path)
    path = Path(name_or_path)
    if not path.is_file():
        raise ConfigError(f"experiment file {str(path)!r} does not exist; names: {resources.names('experiments')}")
    return path


def load_experiment(name_or_path: str | Path) -> Experiment:
    """Read and validate an experiment YAML (every cell's config is resolved, so bad fields fail here).

    Every problem is one ``ConfigError`` naming the file."""
    path = experiment_source(name_or_path)
    raw = read_yaml(path, "experiment file") or {}
    if not isinstance(raw, Mapping):
        raise ConfigError(f"experiment file {str(path)!r} must hold a mapping, got {type(raw).__name__}")
    try:
        return _parse(path, raw)
    except ValueError as exc:                       # ConfigError included
        text = str(exc)
        raise ConfigError(text if text.startswith(str(path)) else f"{path}: {text}") from None
    except KeyError as exc:
        raise ConfigError(f"{path}: a required key is missing: {exc}") from None
    except (TypeError, AttributeError, IndexError) as exc:
        raise ConfigError(f"{path}: malformed experiment ({exc})") from None


def _parse(path: Any, raw: Mapping[str, Any]) -> Experiment:
    unknown = set(raw) - KEYS
    if unknown:
        raise ConfigError(f"{path}: unknown keys {sorted(map(str, unknown))}; known: {sorted(KEYS)}")
    points, xlabel = _points(raw.get("sweep"))
    series = []
    for entry in raw.get("series", []):
        entry = {"solver": entry} if isinstance(entry, str) else dict(entry)
        label = entry.get("label") or solver_name(entry["solver"])
        series.append(Series(label, entry["solver"], dict(entry.get("overrides") or {})))
    labels = [s.label for s in series]
    if not series or len(set(labels)) != len(labels):
        raise ValueError(f"{path}: series need distinct labels, got {labels}")
    baseline = raw.get("baseline")
    checks = [Check(claim=c["claim"], a=c["a"], b=c["b"], test=c["test"], metric=c.get("metric", "score"),
                    at=tuple(_as_list(c.get("at"))), alpha=float(c.get("alpha", 0.01)),
                    ratio=float(c.get("ratio", 1.0))) for c in raw.get("checks", [])]
    for name in [baseline] * (baseline is not None) + [x for c in checks for x in (c.a, c.b)]:
        if name not in labels:
            raise ValueError(f"{path}: {name!r} is not a series label ({labels})")
    for c in checks:
        if c.test not in TESTS:
            raise ValueError(f"{path}: check test {c.test!r} is not one of {TESTS}")
        _select(points, c.at, f"{path} check {c.claim!r}")
    heatmap = _heatmap(raw.get("heatmap"), raw.get("sweep"), labels, path)
    quick = raw.get("quick") or {}
    quick_points = _select(points, quick["points"], f"{path} quick") if "points" in quick else \
        [points[i] for i in sorted({0, len(points) // 2, len(points) - 1})]
    exp = Experiment(
        name=raw.get("name", path.stem), title=raw.get("title", path.stem), source=raw.get("source", ""),
        scenario=str(raw.get("scenario", "default")), overrides=dict(raw.get("overrides") or {}), xlabel=xlabel,
        points=points, series=series, baseline=baseline, metrics=list(raw.get("metrics", ["score"])),
        episodes=_count(raw.get("episodes", 100), "episodes"),
        headline=_select(points, _as_list(raw.get("headline")), str(path)),
        published=str(raw.get("published", "")).strip(), checks=checks, quick_points=quick_points,
        quick_episodes=_count(quick.get("episodes", 2), "quick.episodes"), raw=raw,
        marks=_marks(raw.get("marks"), path),
        reference=_reference(raw.get("reference"), points, path), heatmap=heatmap)
    if exp.marks and exp.heatmap:
        raise ValueError(f"{path}: marks are lines in the sweep plots, which a heatmap experiment does not draw")
    for point in points:
        for s in series:
            exp.config(point, s)
    for metric in [*exp.metrics, *(exp.reference.metrics if exp.reference else ())]:
        if metric not in METRIC_LABELS:
            raise ValueError(f"{path}: unknown metric {metric!r}; known: {sorted(METRIC_LABELS)}")
    return exp


def _marks(raw: Any, path: Any) -> list[Mark]:
    marks = []
    for entry in _as_list(raw):
        if not isinstance(entry, Mapping) or set(entry) - {"metric", "share", "label"} or "metric" not in entry:
            raise ValueError(f"{path}: a mark is {{metric, share, label}}, got {entry!r}")
        if entry["metric"] not in SHARE_METRICS:
            raise ValueError(f"{path}: a mark needs a yes/no metric {SHARE_METRICS}, got {entry['metric']!r}")
        share = float(entry.get("share", 0.5))
        if not 0.0 < share <= 1.0:
            raise ValueError(f"{path}: a mark's share must lie in (0, 1], got {share}")
        label = str(entry.get("label") or f"{METRIC_LABELS[entry['metric']]} on ≥ {100 * share:.0f} % of seeds")
        marks.append(Mark(entry["metric"], share, label))
    return marks


def _reference(raw: Any, points: list[Point], path: Any) -> Reference | None:
    if raw is None:
        return None
    if not isinstance(raw, Mapping) or set(raw) - {"point", "metrics"} or "point" not in raw:
        raise ValueError(f"{path}: reference is {{point, metrics}}, got {raw!r}")
    point = _select(points, [raw["point"]], f"{path} reference")[0]
    return Reference(point, tuple(_as_list(raw.get("metrics")) or ["score"]))


def _heatmap(spec: Mapping[str, Any] | None, sweep: Mapping[str, Any] | None, labels: Sequence[str],
             path: Any) -> Heatmap | None:
    if not spec:
        return None
    grid = (sweep or {}).get("grid") or {}
    if len(grid) != 2:
        raise ValueError(f"{path}: heatmap needs a sweep over a grid of two fields")
    rows, columns = list(grid)
    difference = tuple(spec["difference"]) if spec.get("difference") else None
    heat = Heatmap(rows=rows, columns=columns, baseline=spec["baseline"], series=tuple(spec["series"]),
                   difference=difference, metric=spec.get("metric", "score"))  # type: ignore[arg-type]
    for name in [heat.baseline, *heat.series, *(difference or ())]:
        if name not in labels:
            raise ValueError(f"{path}: heatmap names {name!r}, not a series label ({list(labels)})")
    if difference and (len(difference) != 2 or not set(difference) <= set(heat.series)):
        raise ValueError(f"{path}: heatmap difference must name two of its series, got {difference!r}")
    return heat


def _count(value: Any, key: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ConfigError(f"{key}: got {value!r}; allowed: an integer >= 1")
    return value


def _as_list(value: Any) -> list:
    if value is None:
        return []
    return list(value) if isinstance(value, list) else [value]


# -- running -------------------------------------------------------------------------------------------------------
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


# -- reports -------------------------------------------------------------------------------------------------------
def cells_of(rows: Sequence[Mapping[str, Any]]) -> dict[tuple[str, str], list[Mapping[str, Any]]]:
    """Rows grouped by (point label, series label)."""
    cells: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for row in rows:
        cells.setdefault((str(row["point"]), str(row["series"])), []).append(row)
    return cells


def metric_table(exp: Experiment, cells: Mapping, points: Sequence[Point], metric: str) -> str:
    """Rows: sweep points; columns: series; cells: mean ± sd (``k nc`` = k episodes did not converge)."""
    present = [s.label for s in exp.series if any((p.label, s.label) in cells for p in points)]
    body = [[p.label, *(cell_text(cells[(p.label, s)], metric) if (p.label, s) in cells else "n/a"
                        for s in present)] for p in points]
    return markdown_table([exp.xlabel or "setting", *present], body)


def paired_table(exp: Experiment, cells: Mapping, points: Sequence[Point], metric: str = "score") -> str:
    """Every series against the baseline at each point: mean ± sd, Δ, ratio, p-values, share won and tied."""
    comm = [m for m in COMM_METRICS if m in exp.metrics]
    header = [exp.xlabel or "setting", "series", METRIC_LABELS[metric], *PAIRED_HEADER,
              *(COMM_HEADER[m] for m in comm), "not conv."]
    body = []
    for p in points:
        base = cells.get((p.label, exp.baseline))
        for s in exp.series:
            cell = cells.get((p.label, s.label))
            if cell is None:
                continue
            paired_cols = ["–"] * len(PAIRED_HEADER)
            if base is not None and s.label != exp.baseline:
                paired_cols = paired_columns(compare_cells(cell, base, metric), METRIC_DIGITS.get(metric, 1))
            body.append([p.label, s.label, cell_text(cell, metric), *paired_cols,
                         *(cell_text(cell, m) for m in comm), not_converged(cell)])
    return markdown_table(header, body, align="ll" + "r" * (len(header) - 2))


def evaluate_check(check: Check, cells: Mapping, points: Sequence[Point]) -> tuple[str, str]:
    """(observed figures, verdict) of one published claim; ``n/a`` where the cells were not run."""
    chosen = [p for p in points if not check.at or any(_matches(p, want) for want in check.at)]
    observed, verdicts = [], []
    for p in chosen:
        a, b = cells.get((p.label, check.a)), cells.get((p.label, check.b))
        if a is None or b is None:
            continue
        pc = compare_cells(a, b, check.metric)
        ok = {"greater": pc.mean_diff > 0 and pc.p_t < check.alpha,
              "less": pc.mean_diff < 0 and pc.p_t < check.alpha,
              "same": not pc.p_t < check.alpha,
              "ratio_above": pc.ratio >= check.ratio,
              "ratio_below": pc.ratio < check.ratio}[check.test]
        verdicts.append(ok)
        digits = METRIC_DIGITS.get(check.metric, 1)
        if len(chosen) > 1:     # the per-point details are in the tables; keep the claim's row short
            observed.append(f"{p.label}: ×{pc.ratio:.3f}, p {format_p(pc.p_t)}")
        else:
            observed.append(f"Δ {pc.mean_diff:+.{digits}f} (×{pc.ratio:.3f}), p {format_p(pc.p_t)}, "
                            f"higher on {100 * pc.better:.0f} % of seeds")
    if not verdicts:
        return "not run", "n/a"
    verdict = "yes" if all(verdicts) else ("no" if not any(verdicts) else f"partly ({sum(verdicts)}/{len(verdicts)})")
    return "; ".join(observed), verdict


def mark_points(exp: Experiment, cells: Mapping, points: Sequence[Point]) -> list[tuple[Mark, Point | None]]:
    """Each mark with the first point at which its share of episodes (every series pooled) reaches the threshold."""
    found = []
    for mark in exp.marks:
        hit = None
        for p in points:
            x = np.concatenate([values(cells[(p.label, s.label)], mark.metric) for s in exp.series
                                if (p.label, s.label) in cells] or [np.zeros(0)])
            x = x[np.isfinite(x)]
            if x.size and x.mean() >= mark.share - 1e-12:
                hit = p
                break
        found.append((mark, hit))
    return found


def marks_note(exp: Experiment, marks: Sequence[tuple[Mark, Point | None]]) -> str:
    parts = [f"{m.label} from {exp.xlabel} = {p.label}" if p is not None else f"{m.label}: at no point"
             for m, p in marks]
    return "Marked in the plots (episodes of every series pooled): " + "; ".join(parts) + ".\n"


def _against_reference(cells: Mapping, point: Point, ref: Point, series: str, metric: str) -> PairedComparison | None:
    a, b = cells.get((point.label, series)), cells.get((ref.label, series))
    if a is None or b is None:
        return None
    return compare_cells(a, b, metric)


def reference_table(exp: Experiment, cells: Mapping, points: Sequence[Point], ref: Point, metric: str) -> str:
    """Every series at every point against itself at ``ref``: mean ± sd, Δ with its 95 % t-interval, ratio, p (t),
    share of seeds above and tied; ``same instances`` says whether the paired seeds drew identical problems."""
    digits = METRIC_DIGITS.get(metric, 1)
    body = []
    for s in exp.series:
        for p in points:
            pc = _against_reference(cells, p, ref, s.label, metric)
            if pc is None:
                continue
            if p == ref:
                body.append([p.label, s.label, cell_text(cells[(p.label, s.label)], metric), "reference", "", "",
                             "", ""])
                continue
            same = {r["instance"] for r in cells[(p.label, s.label)]} == {r["instance"] for r in
                                                                         cells[(ref.label, s.label)]}
            ci = "–" if np.isnan(pc.ci95[0]) else f"[{pc.ci95[0]:+.{digits}f}, {pc.ci95[1]:+.{digits}f}]"
            body.append([p.label, s.label, cell_text(cells[(p.label, s.label)], metric),
                         f"{pc.mean_diff:+.{digits}f} {ci}" + ("" if same else " †"),
                         "–" if np.isnan(pc.ratio) else f"{pc.ratio:.3f}", format_p(pc.p_t),
                         f"{100 * pc.better:.0f} %", f"{100 * pc.tied:.0f} %"])
    header = [exp.xlabel or "setting", "series", METRIC_LABELS[metric], "Δ vs reference [95 % CI]", "ratio",
              "p (t)", "above", "ties"]
    table = markdown_table(header, body, align="ll" + "r" * (len(header) - 2))
    if any(" †" in str(row[3]) for row in body):
        table += "\n† the same seeds drew different instances here: paired by seed, not by instance.\n"
    return table


def checks_table(exp: Experiment, cells: Mapping, points: Sequence[Point]) -> str:
    body = [[c.claim, *evaluate_check(c, cells, points)] for c in exp.checks]
    return markdown_table(["published claim", "ours", "reproduced"], body, align="llc")


def write_reports(exp: Experiment, rows: Sequence[Mapping[str, Any]], target: Path, points: Sequence[Point],
                  docs: Path | None = None) -> None:
    """table.md and the PNGs from ``rows``; with ``docs``, the experiment's block of the results page."""
    cells = cells_of(rows)
    points = [p for p in points if any((p.label, s.label) in cells for s in exp.series)]
    headline = [p for p in exp.headline if p in points]
    seeds_run = max((len(c) for c in cells.values()), default=0)
    figures = []
    marks = mark_points(exp, cells, points)
    if exp.heatmap:
        figures += heatmap_figures(exp, cells, points, target, seeds_run)
    elif len(points) > 1:
        for metric in exp.metrics:
            series = {s.label: [cells.get((p.label, s.label), []) for p in points] for s in exp.series}
            sweep_plot(target / f"{metric}.png", [p.x for p in points], series, metric, exp.xlabel,
                       f"{exp.title}\n{METRIC_LABELS[metric]}, {seeds_run} paired seeds per point",
                       marks=[(p.x, f"{m.label} ({exp.xlabel} = {p.label})") for m, p in marks if p is not None])
            figures.append(f"{metric}.png")
    ref = exp.reference if exp.reference and exp.reference.point in points and len(points) > 1 else None
    if ref is not None:
        for metric in ref.metrics:
            diffs = {s.label: [_against_reference(cells, p, ref.point, s.label, metric) for p in points]
                     for s in exp.series}
            reference_plot(target / f"delta_{metric}.png", [p.x for p in points], diffs, metric, exp.xlabel,
                           f"{exp.xlabel} = {ref.point.label}",
                           f"{exp.title}\npaired against {exp.xlabel} = {ref.point.label}, {seeds_run} seeds")
            figures.append(f"delta_{metric}.png")
    for p in headline or ([] if len(points) > 1 else points):
        name = "headline.png" if len(points) == 1 else f"headline_{_slug(p.label)}.png"
        present = {s.label: cells[(p.label, s.label)] for s in exp.series if (p.label, s.label) in cells}
        title = f"{exp.xlabel} = {p.label}" if exp.xlabel else exp.title
        bar_and_differences(target / name, present, exp.baseline, "score", f"{title}: score, {seeds_run} seeds")
        figures.append(name)
    skipped = json.loads((target / "run.json").read_text()).get("skipped", []) if (target / "run.json").exists() \
        else []
    sections = [f"# {exp.title}\n", f"Source: {exp.source}. {seeds_run} paired seeds per cell.\n"]
    for metric in exp.metrics:
        sections.append(f"## {METRIC_LABELS[metric]} ({_how(metric)})\n\n" + metric_table(exp, cells, points, metric))
    if exp.heatmap:
        sections.append(heatmap_tables(exp, cells, points, level="##"))
    if exp.baseline:
        sections.append(f"## Paired against {exp.baseline} (score)\n\n" + paired_table(exp, cells, points))
    if ref is not None:
        for metric in ref.metrics:
            sections.append(f"## Paired against {exp.xlabel} = {ref.point.label} ({METRIC_LABELS[metric]}, same "
                            "series, same seeds)\n\n" + reference_table(exp, cells, points, ref.point, metric))
    if marks:
        sections.append(marks_note(exp, marks))
    if exp.checks:
        sections.append("## Published claims\n\n" + checks_table(exp, cells, points))
    sections.append(_convergence_note(rows, skipped))
    sections.append("\n".join(f"![{f}]({f})" for f in figures) + "\n")
    (target / "table.md").write_text("\n".join(sections))
    if docs is not None:
        block = _docs_block(exp, cells, points, headline, figures, target, docs, rows, skipped, marks, ref)
        update_docs(docs, exp.name, exp.title, block)


def heatmap_maps(exp: Experiment, cells: Mapping, points: Sequence[Point]) -> tuple[list, list, dict[str, Any]]:
    """Row values, column values and, per map title, the (R, C) array of percent changes (nan where not run)."""
    heat = exp.heatmap
    assert heat is not None
    grid = exp.raw["sweep"]["grid"]
    rows, cols = list(grid[heat.rows]), list(grid[heat.columns])
    maps: dict[str, Any] = {}
    for label in heat.series:
        table = np.full((len(rows), len(cols)), np.nan)
        for p in points:
            a, b = cells.get((p.label, label)), cells.get((p.label, heat.baseline))
            if a and b:
                pc = compare_cells(a, b, heat.metric)
                table[rows.index(p.overrides[heat.rows]), cols.index(p.overrides[heat.columns])] = 100 * (pc.ratio - 1)
        maps[f"{label} over {heat.baseline}"] = table
    if heat.difference:
        a, b = heat.difference
        maps[f"{a} minus {b}"] = maps[f"{a} over {heat.baseline}"] - maps[f"{b} over {heat.baseline}"]
    return rows, cols, maps


def heatmap_tables(exp: Experiment, cells: Mapping, points: Sequence[Point], level: str = "##") -> str:
    """One markdown table per map: rows × columns of the grid, percent change of the mean (1 decimal)."""
    heat = exp.heatmap
    assert heat is not None
    rows, cols, maps = heatmap_maps(exp, cells, points)
    parts = []
    for title, table in maps.items():
        what = "percentage points" if " minus " in title else f"% change of the mean {METRIC_LABELS[heat.metric]}"
        head = f"{title} ({what}; rows {heat.rows}, columns {heat.columns})"
        head = f"{level} {head}\n\n" if level.startswith("#") else f"**Ours, {head}:**\n\n"
        body = [[r, *(_signed(v) for v in table[k])] for k, r in enumerate(rows)]
        parts.append(head + markdown_table([f"{heat.rows} \\ {heat.columns}", *cols], body))
    return "\n".join(parts)


def _signed(value: float) -> str:
    """``+1.2`` / ``-3.4``; ``0.0`` for anything that rounds to zero; ``n/a`` for a cell that was not run."""
    if np.isnan(value):
        return "n/a"
    text = f"{value:+.1f}"
    return "0.0" if text in ("+0.0", "-0.0") else text


def heatmap_figures(exp: Experiment, cells: Mapping, points: Sequence[Point], target: Path,
                    seeds_run: int) -> list[str]:
    heat = exp.heatmap
    assert heat is not None
    rows, cols, maps = heatmap_maps(exp, cells, points)
    names = []
    for title, table in maps.items():
        name = f"heatmap_{_slug(title)}.png"
        heatmap_plot(target / name, table, rows, cols, heat.rows, heat.columns,
                     f"{exp.title}\n{title}, % ({seeds_run} paired seeds per cell)", diverging=" minus " in title)
        names.append(name)
    return names


def _convergence_note(rows: Sequence[Mapping[str, Any]], skipped: Sequence[str]) -> str:
    bad = not_converged(rows)
    note = (f"Not converged within the round bound: {bad} of {len(rows)} episodes (kept in every figure, marked "
            "`nc` per cell)." if bad else f"Every one of the {len(rows)} episodes converged.")
    if skipped:
        note += " Not applicable, not run: " + "; ".join(sorted(set(skipped))) + "."
    return note + "\n"


def _docs_block(exp: Experiment, cells: Mapping, points: Sequence[Point], headline: Sequence[Point],
                figures: Sequence[str], target: Path, docs: Path, rows: Sequence[Mapping[str, Any]],
                skipped: Sequence[str], marks: Sequence[tuple[Mark, Point | None]] = (),
                ref: Reference | None = None) -> str:
    seeds_run = max((len(c) for c in cells.values()), default=0)
    rel = Path(_relpath(target, docs.parent))
    setting = ", ".join(f"{k} = {_label(v)}" for k, v in exp.overrides.items())
    parts = [f"*Source: {exp.source}. Scenario `{exp.scenario}`{', ' + setting if setting else ''}; "
             f"{seeds_run} paired seeds per cell (seeds 0–{seeds_run - 1}). Regenerate: "
             f"`taskalloc experiments run configs/experiments/{exp.name}.yaml --overwrite`. "
             f"Full tables: [{rel}/table.md]({rel}/table.md), per-episode data: `{rel}/episodes.csv`.*\n"]
    if exp.published:
        parts.append(f"**Published:** {exp.published}\n")
    if exp.heatmap:         # the maps stand for the per-point tables (in table.md)
        parts.append(heatmap_tables(exp, cells, points, level="bold"))
    else:
        for metric in exp.metrics:
            parts.append(f"**Ours, {METRIC_LABELS[metric]}** ({_how(metric)}):\n\n"
                         + metric_table(exp, cells, points, metric))
    if exp.baseline and headline:
        parts.append(f"**Ours, paired against {exp.baseline}** at the headline setting:\n\n"
                     + paired_table(exp, cells, headline))
    if ref is not None:
        for metric in ref.metrics:
            parts.append(f"**Ours, paired against {exp.xlabel} = {ref.point.label}** ({METRIC_LABELS[metric]}; each "
                         "series against itself on the same seeds):\n\n"
                         + reference_table(exp, cells, points, ref.point, metric))
    if marks:
        parts.append(marks_note(exp, marks))
    if exp.checks:
        parts.append("**Published claims on our data:**\n\n" + checks_table(exp, cells, points))
    parts.append(_convergence_note(rows, skipped))
    parts.append(" ".join(f"![{exp.name} {f}]({rel}/{f})" for f in figures) + "\n")
    return "\n".join(parts)


def _how(metric: str) -> str:
    return "share of episodes" if metric in SHARE_METRICS else "mean ± sd"


def _relpath(path: Path, start: Path) -> str:
    return os.path.relpath(path.resolve(), start.resolve())


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", text).strip("_") or "point"


def update_docs(docs: Path, name: str, title: str, block: str) -> None:
    """Replace the text between the ``name`` markers in ``docs`` (append a ``title`` section if they are missing)."""
    start, end = f"<!-- results:{name}:start -->", f"<!-- results:{name}:end -->"
    text = docs.read_text() if docs.exists() else "# Results\n"
    generated = f"{start}\n{block}{end}"
    if start in text and end in text:
        head, rest = text.split(start, 1)
        text = head + generated + rest.split(end, 1)[1]
    else:
        text = text.rstrip("\n") + f"\n\n## {title}\n\n{generated}\n"
    docs.write_text(text)


def check_docs(docs: Path, name: str, overwrite: bool) -> None:
    """Refuse a results page that is not one: an existing file must carry ``<!-- results:… -->`` markers (so a typo
    such as ``--docs README.md`` changes nothing), and a block of ``name`` already on it is replaced only with
    ``overwrite``; a new page is created only as a ``.md`` file in an existing folder."""
    if docs.exists():
        text = resources.read_bounded(docs, MAX_DOCS_BYTES, "results page").decode("utf-8", errors="replace")
        if "<!-- results:" not in text:
            raise ConfigError(f"{docs} is not a results page (it carries no <!-- results:NAME:start --> markers); "
                              "name the results page, or --no-docs to leave the page alone")
        if not overwrite and f"<!-- results:{name}:start -->" in text:
            raise ConfigError(f"{docs} already holds the results of {name}; pass --overwrite to replace them, or "
                              "--no-docs to leave the page alone")
    elif docs.suffix != ".md" or not docs.parent.is_dir():
        raise ConfigError(f"{docs} does not exist; a new results page must be a .md file in an existing folder")


def report_experiment(exp: Experiment, out: Path, docs: Path | None) -> None:
    """Tables, plots and docs again from ``<out>/<name>/episodes.csv`` (no episodes are run)."""
    target = out / exp.name
    rows = read_csv(target / "episodes.csv")
    labels = {str(r["point"]) for r in rows}
    write_reports(exp, rows, target, [p for p in exp.points if p.label in labels], docs=docs)


# -- command line --------------------------------------------------------------------------------------------------
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


def suite_block(experiments: Sequence[Experiment], out: Path, docs: Path) -> str:
    """The run summary of every experiment (episodes, wall and CPU time, jobs, commit) from the run.json files."""
    body, wall, cpu = [], 0.0, 0.0
    info: dict[str, Any] = {}
    for exp in experiments:
        path = out / exp.name / "run.json"
        if not path.exists():
            continue
        info = json.loads(path.read_text())
        wall, cpu = wall + info["wall_seconds"], cpu + info.get("cpu_seconds", 0.0)
        rel = _relpath(out / exp.name, docs.parent)
        body.append([f"[{exp.name}]({rel}/table.md)", info["episodes_per_cell"], info["episodes_total"],
                     f"{info['wall_seconds']:.0f}", f"{info.get('cpu_seconds', 0.0):.0f}", info["jobs"]])
    body.append(["**total**", "", sum(int(r[2]) for r in body), f"{wall:.0f}", f"{cpu:.0f}", ""])
    packages = ", ".join(f"{k} {v}" for k, v in info.get("packages", {}).items())
    return (markdown_table(["experiment", "seeds per cell", "episodes", "wall s", "CPU s", "jobs"], body)
            + f"\nPython {info.get('python')}, {packages}; commit `{info.get('git_commit')}`"
            + (" (with uncommitted changes)" if info.get("git_dirty") else "") + f"; {info.get('platform')}.\n")


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
