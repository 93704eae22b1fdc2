"""Experiment files: the YAML model of an experiment (sweep points, series, checks, marks, reference, heat map),
read and validated before anything runs (thesis §3.3, §5.3 as files; the file format is ours).

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

import dataclasses
import itertools
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from taskalloc.evaluation.episodes import solver_name
from taskalloc.evaluation.report import METRIC_LABELS, SHARE_METRICS
from taskalloc_env import TaskAllocConfig, resolve_config, resources
from taskalloc_env.config import read_yaml
from taskalloc_env.errors import ConfigError

KEYS = {"name", "title", "source", "scenario", "overrides", "sweep", "series", "baseline", "metrics", "episodes",
        "headline", "published", "checks", "quick", "marks", "reference", "heatmap"}
TESTS = ("greater", "less", "same", "ratio_above", "ratio_below")


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
        points = [Point(" × ".join(value_label(v) for v in combo), " × ".join(value_label(v) for v in combo),
                        dict(zip(fields, combo))) for combo in combos]
        return points, sweep.get("label", " × ".join(fields))
    if "field" in sweep:
        field = sweep["field"]
        points = [Point(value_label(v), v, {field: v}) for v in sweep["values"]]
        return points, sweep.get("label", field)
    points = []
    for entry in sweep["points"]:
        entry = dict(entry)
        label = str(entry.pop("label", None) or ", ".join(f"{k}={value_label(v)}" for k, v in entry.items()))
        x = entry.get(sweep["x"], label) if "x" in sweep else label
        points.append(Point(label, x, entry))
    return points, sweep.get("label", sweep.get("x", "point"))


def value_label(value: Any) -> str:
    """A config value as a point label: a list or tuple joined with ``/``."""
    return "/".join(map(str, value)) if isinstance(value, (list, tuple)) else str(value)


def _select(points: list[Point], wanted: Sequence[Any], where: str) -> list[Point]:
    """Points matching ``wanted`` entries: a mapping of config values, or a point label."""
    chosen = []
    for want in wanted:
        hits = [p for p in points if point_matches(p, want)]
        if not hits:
            raise ValueError(f"{where}: {want!r} matches no sweep point ({[p.label for p in points]})")
        chosen += [p for p in hits if p not in chosen]
    return chosen


def point_matches(point: Point, want: Any) -> bool:
    """Whether ``point`` is ``want``: a mapping of config values it sets, or its label."""
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
