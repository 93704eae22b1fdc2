"""Result rows → arrays, markdown tables, CSV files and PNG plots (shared by the compare command and the runner).

A *row* is one episode (``taskalloc.evaluation.episodes.run_episode``). Rows of one cell (same point, same series) are
sorted by seed, so cells of different series line up seed by seed for the paired statistics
(``taskalloc.evaluation.stats``).
"""

from __future__ import annotations

import csv
import textwrap
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from taskalloc.evaluation.stats import PairedComparison, ci95_half, format_mean_sd, format_p, paired
from taskalloc_env.errors import ConfigError

METRIC_LABELS = {
    "score": "score", "valid_tasks": "valid tasks", "conflicts": "conflicts", "rounds": "rounds",
    "messages": "messages", "comm_steps": "comm steps / agent", "informative_messages": "informative msgs",
    "data_items": "data items", "bids": "bids", "quits": "quits", "quits_seen": "quits seen",
    "rounds_to_agreement": "rounds to agreement",
    "comm_steps_to_agreement": "comm steps / agent to agreement", "invalid_actions": "invalid actions",
    "messages_lost": "messages lost", "messages_delayed": "messages delayed",
    "data_received_per_agent": "data items received / agent", "data_sent_per_agent": "data items sent / agent",
    "data_per_assignment": "data items / assignment made",
    "data_per_agent_per_assignment": "data items / agent / assignment (Σ L_j)",
    "conflicting_bids_per_agent": "conflicting bids / agent",
    "dropped_agents": "failed agents", "connected": "connected network", "fully_connected": "fully connected",
    "converged": "converged", "completion": "share of tasks serviced", "score_per_task": "score / serviced task",
    "workload_gini": "workload Gini (tasks / agent)", "max_travel": "longest flight",
    "max_agent_messages": "most messages sent by one agent",
}
METRIC_DIGITS = {"score": 0, "valid_tasks": 1, "conflicts": 1, "rounds": 1, "messages": 0, "comm_steps": 1,
                 "informative_messages": 0, "data_items": 0, "bids": 0, "quits": 1, "quits_seen": 1,
                 "rounds_to_agreement": 1, "comm_steps_to_agreement": 1, "invalid_actions": 1, "messages_lost": 0,
                 "messages_delayed": 0,
                 "data_received_per_agent": 0, "data_sent_per_agent": 0, "data_per_assignment": 0,
                 "data_per_agent_per_assignment": 2,
                 "conflicting_bids_per_agent": 2, "dropped_agents": 2, "connected": 2, "fully_connected": 2,
                 "converged": 2, "completion": 2, "score_per_task": 0, "workload_gini": 2, "max_travel": 1,
                 "max_agent_messages": 0}
# yes/no figures: a cell shows the share of its episodes (``62 %``), a plot the share with its 95 % interval
SHARE_METRICS = ("connected", "fully_connected", "converged")


def refuse_existing(folder: Path, overwrite: bool, option: str = "--out") -> None:
    """Refuse (``ConfigError``) to write into a folder that exists and holds files, unless ``overwrite``."""
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"{option} {folder}: exists and is not a folder")
    if not overwrite and folder.is_dir() and any(folder.iterdir()):
        raise ConfigError(f"{option} {folder}: exists and is not empty; pass --overwrite to replace its files, or "
                          "choose another folder")


def values(rows: Iterable[Mapping[str, Any]], metric: str) -> np.ndarray:
    """The metric of ``rows`` in seed order; missing values (None, '') become nan, yes/no ones 1 and 0 (a CSV
    holds them as ``True``/``False``)."""
    ordered = sorted(rows, key=lambda r: int(r["seed"]))
    return np.array([_number(r.get(metric)) for r in ordered])


def _number(value: Any) -> float:
    if value in (None, ""):
        return np.nan
    if isinstance(value, str) and value in ("True", "False", "true", "false"):
        return float(value in ("True", "true"))
    return float(value)


def seeds(rows: Iterable[Mapping[str, Any]]) -> list[int]:
    return sorted(int(r["seed"]) for r in rows)


def not_converged(rows: Iterable[Mapping[str, Any]]) -> int:
    """Episodes that hit the round bound (kept in every figure, counted here)."""
    return sum(str(r["converged"]) in ("False", "false", "0") for r in rows)


def cell_text(rows: Sequence[Mapping[str, Any]], metric: str) -> str:
    """``mean ± sd`` of a cell, with ``(k nc)`` when k of its episodes did not converge; ``–`` if no values."""
    x = values(rows, metric)
    x = x[~np.isnan(x)]
    if metric in SHARE_METRICS:
        text = f"{100 * x.mean():.0f} %" if x.size else "–"
    else:
        text = format_mean_sd(x, METRIC_DIGITS.get(metric, 1)) if x.size else "–"
    bad = not_converged(rows)
    return f"{text} ({bad} nc)" if bad else text


def compare_cells(a: Sequence[Mapping[str, Any]], b: Sequence[Mapping[str, Any]], metric: str) -> PairedComparison:
    """Paired figures of cell a against cell b; they must hold the same seeds."""
    if seeds(a) != seeds(b):
        raise ValueError("paired cells must hold the same seeds")
    return paired(values(a, metric), values(b, metric))


def markdown_table(header: Sequence[str], body: Iterable[Sequence[Any]], align: str | None = None) -> str:
    """A GitHub markdown table; ``align`` is one character per column (l, r, c), default left then right."""
    align = align or "l" + "r" * (len(header) - 1)
    marks = {"l": ":--", "r": "--:", "c": ":-:"}
    lines = ["| " + " | ".join(map(str, header)) + " |", "|" + "|".join(marks[a] for a in align) + "|"]
    lines += ["| " + " | ".join(map(str, row)) + " |" for row in body]
    return "\n".join(lines) + "\n"


def paired_columns(pc: PairedComparison, digits: int = 0) -> list[str]:
    """Δ mean, ratio, p (t), p (Wilcoxon), share better, share tied."""
    if np.isnan(pc.mean_diff):
        return ["–"] * 6
    ratio = "–" if np.isnan(pc.ratio) else f"{pc.ratio:.3f}"
    return [f"{pc.mean_diff:+.{digits}f}", ratio, format_p(pc.p_t), format_p(pc.p_wilcoxon),
            f"{100 * pc.better:.0f} %", f"{100 * pc.tied:.0f} %"]


PAIRED_HEADER = ("Δ mean", "ratio", "p (t)", "p (Wilcoxon)", "beats", "ties")


def write_csv(path: Path, rows: Sequence[Mapping[str, Any]], fields: Sequence[str] | None = None) -> None:
    """Rows as CSV (columns: ``fields`` or the union of the rows' keys in first-seen order)."""
    if fields is None:
        fields = list(dict.fromkeys(k for r in rows for k in r))
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields, lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _csv_value(row.get(k)) for k in fields})


def _csv_value(value: Any) -> Any:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.6g}"
    return value


def read_csv(path: Path) -> list[dict[str, Any]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


# -- plots ---------------------------------------------------------------------------------------------------------
def bar_and_differences(path: Path, cells: Mapping[str, Sequence[Mapping[str, Any]]], baseline: str | None,
                        metric: str = "score", title: str = "") -> None:
    """Left: each series' mean with its 95 % t-interval (the axis spans the data, not 0). Right: per-seed paired
    differences against ``baseline`` with their mean and 95 % t-interval, so a few per cent show."""
    labels = list(cells)
    data = [values(cells[k], metric) for k in labels]
    others = [k for k in labels if baseline in cells and k != baseline and seeds(cells[k]) == seeds(cells[baseline])]
    fig, axes = plt.subplots(1, 2 if others else 1, figsize=(12 if others else 6, 4.4), squeeze=False)
    name = METRIC_LABELS.get(metric, metric)
    ax = axes[0, 0]
    for n, x in enumerate(data):
        finite = x[np.isfinite(x)]
        if finite.size:
            ax.errorbar(n, finite.mean(), yerr=ci95_half(finite), fmt="o", capsize=5, color="tab:blue")
    ax.set_xticks(range(len(labels)), labels, rotation=30, ha="right")
    ax.set_ylabel(f"{name} (mean, 95 % CI)")
    ax.grid(axis="y", alpha=0.3)
    ax.set_title(textwrap.fill(title or f"{name}, {len(data[0])} seeds", 60), fontsize=9)
    if others:
        ax = axes[0, 1]
        base = values(cells[baseline], metric)
        diffs = [values(cells[k], metric) - base for k in others]
        ax.axhline(0, color="grey", lw=0.8)
        rng = np.random.default_rng(0)
        for n, d in enumerate(diffs):
            ax.scatter(n + rng.uniform(-0.2, 0.2, d.size), d, s=8, alpha=0.35, color="tab:orange")
            ax.errorbar(n, d.mean(), yerr=ci95_half(d), fmt="D", capsize=6, color="k", zorder=3)
        ax.set_xticks(range(len(others)), others, rotation=30, ha="right")
        ax.set_ylabel(f"{name} − {baseline}, per seed (mean, 95 % CI)")
        ax.grid(axis="y", alpha=0.3)
        ax.set_title(f"paired differences vs {baseline}", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def sweep_plot(path: Path, xs: Sequence[Any], series: Mapping[str, Sequence[Sequence[Mapping[str, Any]]]],
               metric: str, xlabel: str, title: str = "", marks: Sequence[tuple[Any, str]] = ()) -> None:
    """Mean ± sd of ``metric`` against the sweep value, one line per series (categorical x if not numeric); a share
    (``SHARE_METRICS``) with its 95 % interval instead. ``marks``: (x, label) pairs drawn as vertical lines."""
    numeric = all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in xs)
    pos = np.asarray(xs, dtype=float) if numeric else np.arange(len(xs), dtype=float)
    fig, ax = plt.subplots(figsize=(8.0, 4.2))
    width = 0.8 / max(1, len(series))
    share = metric in SHARE_METRICS
    for k, (label, cells) in enumerate(series.items()):
        stats_ = [values(c, metric) for c in cells]
        mean = np.array([np.nanmean(s) if np.isfinite(s).any() else np.nan for s in stats_])
        if share:
            sd = np.array([ci95_half(s[np.isfinite(s)]) for s in stats_])
        else:
            sd = np.array([np.nanstd(s, ddof=1) if np.isfinite(s).sum() > 1 else 0.0 for s in stats_])
        if np.isnan(mean).all():
            continue
        if numeric:     # small offsets keep the error bars of overlapping series apart
            step = np.min(np.diff(pos)) if len(pos) > 1 else 1.0
            shift = (k - (len(series) - 1) / 2) * 0.04 * step
            ax.errorbar(pos + shift, mean, yerr=sd, marker="o", ms=3, capsize=2, lw=1.2, label=label)
        else:
            ax.bar(pos + (k - (len(series) - 1) / 2) * width, mean, width, yerr=sd, capsize=2, label=label)
    for n, (x, text) in enumerate(marks):
        where = float(x) if numeric else float(list(xs).index(x))
        ax.axvline(where, color=("tab:red", "tab:purple", "tab:brown", "tab:grey")[n % 4], ls="--", lw=1.0,
                   label=text)
    if not numeric:
        ax.set_xticks(pos, [str(x) for x in xs], rotation=20, ha="right")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(f"{METRIC_LABELS.get(metric, metric)} ({'share, 95 % CI' if share else 'mean ± sd'})")
    _save_with_legend(fig, ax, path, title)


def _save_with_legend(fig: Any, ax: Any, path: Path, title: str) -> None:
    """Title, legend outside the axes on the right, grid; saved to ``path`` and closed."""
    ax.set_title(textwrap.fill(title, 70), fontsize=9)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def reference_plot(path: Path, xs: Sequence[Any], diffs: Mapping[str, Sequence[PairedComparison | None]],
                   metric: str, xlabel: str, reference: str, title: str = "") -> None:
    """Paired differences against the reference point (same series, same seeds): mean Δ with its 95 % t-interval,
    one line per series (categorical x if not numeric)."""
    numeric = all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in xs)
    pos = np.asarray(xs, dtype=float) if numeric else np.arange(len(xs), dtype=float)
    step = np.min(np.diff(pos)) if len(pos) > 1 else 1.0
    fig, ax = plt.subplots(figsize=(8.0, 4.2))
    ax.axhline(0, color="grey", lw=0.8)
    for k, (label, comparisons) in enumerate(diffs.items()):
        mean = np.array([np.nan if c is None else c.mean_diff for c in comparisons])
        low = np.array([np.nan if c is None else c.mean_diff - c.ci95[0] for c in comparisons])
        high = np.array([np.nan if c is None else c.ci95[1] - c.mean_diff for c in comparisons])
        if np.isnan(mean).all():
            continue
        shift = (k - (len(diffs) - 1) / 2) * 0.04 * step
        ax.errorbar(pos + shift, mean, yerr=np.nan_to_num(np.vstack([low, high])), marker="o", ms=3, capsize=3,
                    lw=1.2, label=label)
    if not numeric:
        ax.set_xticks(pos, [str(x) for x in xs], rotation=20, ha="right")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(f"Δ {METRIC_LABELS.get(metric, metric)} vs {reference} (mean, 95 % CI)")
    _save_with_legend(fig, ax, path, title)


def heatmap_plot(path: Path, table: np.ndarray, rows: Sequence[Any], cols: Sequence[Any], row_label: str,
                 col_label: str, title: str = "", diverging: bool = False) -> None:
    """A heat map of ``table`` (R, C) with every cell annotated; ``diverging`` centres the colours on 0."""
    fig, ax = plt.subplots(figsize=(1.0 + 0.75 * len(cols), 1.2 + 0.42 * len(rows)))
    finite = table[np.isfinite(table)]
    if diverging:
        span = float(np.abs(finite).max()) if finite.size else 1.0
        image = ax.imshow(table, cmap="RdBu", vmin=-span, vmax=span, aspect="auto", origin="lower")
    else:
        image = ax.imshow(table, cmap="gray", aspect="auto", origin="lower")   # darker: lower, as the thesis's maps
    for (r, c), v in np.ndenumerate(table):
        if np.isfinite(v):
            low = (v - finite.min()) / max(np.ptp(finite), 1e-9) if not diverging else 0.5 + v / (2 * span or 1)
            colour = "white" if (not diverging and low < 0.5) or (diverging and abs(low - 0.5) > 0.3) else "black"
            ax.text(c, r, f"{v:.0f}" if abs(v) >= 0.5 else "0", ha="center", va="center", fontsize=7, color=colour)
    ax.set_xticks(range(len(cols)), [str(c) for c in cols])
    ax.set_yticks(range(len(rows)), [str(r) for r in rows])
    ax.set_xlabel(col_label)
    ax.set_ylabel(row_label)
    ax.set_title("\n".join(textwrap.fill(line, 60) for line in title.split("\n")), fontsize=9)
    fig.colorbar(image, ax=ax, label="%" if not diverging else "percentage points")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
