"""Experiment reports: from the episode rows of an experiment, its tables (per-metric means, paired comparisons
against the baseline and a reference point, the published claims checked), its figures and its block of the results
page (the paired design of thesis §5.3.1; the layout is ours).
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from taskalloc.evaluation.experiment_files import Check, Experiment, Mark, Point, Reference, point_matches, value_label
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
    reference_plot,
    sweep_plot,
    values,
)
from taskalloc.evaluation.stats import PairedComparison, format_p
from taskalloc_env import resources
from taskalloc_env.errors import ConfigError

MAX_DOCS_BYTES = 16 << 20       # the results page is about 100 kB
COMM_METRICS = ("comm_steps", "comm_steps_to_agreement")     # one message per agent, to the end / to agreement
COMM_HEADER = {"comm_steps": "comm steps (end)", "comm_steps_to_agreement": "comm steps (agreement)"}


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
    chosen = [p for p in points if not check.at or any(point_matches(p, want) for want in check.at)]
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
    sections += _closing_notes(exp, cells, points, marks, rows, skipped, "## Published claims\n\n")
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


def _closing_notes(exp: Experiment, cells: Mapping, points: Sequence[Point], marks: Sequence[tuple[Mark, Point | None]],
                   rows: Sequence[Mapping[str, Any]], skipped: Sequence[str], claims_head: str) -> list[str]:
    """The sections that close a report: where the marks fall, the published claims checked, convergence."""
    notes = [marks_note(exp, marks)] if marks else []
    if exp.checks:
        notes.append(claims_head + checks_table(exp, cells, points))
    return [*notes, _convergence_note(rows, skipped)]


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
    setting = ", ".join(f"{k} = {value_label(v)}" for k, v in exp.overrides.items())
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
    parts += _closing_notes(exp, cells, points, marks, rows, skipped, "**Published claims on our data:**\n\n")
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
