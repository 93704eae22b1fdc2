"""Learning curves with intervals across training seeds, from the ``eval.csv`` files the trainers write.

Each point is the greedy policy's mean score on the validation seeds divided by CBGABI's on the same seeds (the
``ratio`` column of ``taskalloc mappo``; ``score / baseline_score`` for ``taskalloc train``); a method's line is the
mean over its training seeds and its band the 95 % t-interval across them (Student t, k − 1 degrees of freedom).
"""

from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from scipy import stats

from taskalloc_env.errors import ConfigError

Curve = list[tuple[int, float]]


def read_eval(path: Path) -> dict[str, Curve]:
    """An eval.csv → per validation entry, (agent steps, score / CBGABI's) pairs (MAPPO's ``entry`` column; SB3's
    single scenario is ``train_small``)."""
    try:
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise ConfigError(f"cannot read {str(path)!r}: {exc.strerror or exc}") from None
    if not rows or "score" not in rows[0] or not {"steps", "timesteps"} & set(rows[0]):
        raise ConfigError(f"{str(path)!r} is not an eval.csv of taskalloc mappo or taskalloc train")
    curves: dict[str, Curve] = {}
    for r in rows:
        steps = int(float(r.get("steps") or r["timesteps"]))
        ratio = float(r["ratio"]) if r.get("ratio") else float(r["score"]) / float(r["baseline_score"])
        curves.setdefault(r.get("entry") or "train_small", []).append((steps, ratio))
    return curves


def mean_and_band(per_seed: Sequence[Curve]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(steps, mean over seeds, half-width of the 95 % t-interval; 0 for one seed) over the common length."""
    n = min(len(c) for c in per_seed)
    steps = np.array([p[0] for p in per_seed[0][:n]])
    ratio = np.array([[p[1] for p in c[:n]] for c in per_seed])
    k = len(per_seed)
    half = (stats.t.ppf(0.975, k - 1) * ratio.std(axis=0, ddof=1) / np.sqrt(k)) if k > 1 else np.zeros(n)
    return steps, ratio.mean(axis=0), half


def plot_bands(out: Path, methods: Mapping[str, Sequence[Mapping[str, Curve]]],
               entries: Sequence[str] | None = None) -> None:
    """One panel per validation entry; per method (label → its seeds' curves) the mean and the 95 % band."""
    entries = list(entries or dict.fromkeys(e for runs in methods.values() for run in runs for e in run))
    fig, axes = plt.subplots(1, len(entries), figsize=(1 + 4.6 * len(entries), 4.2), squeeze=False)
    axes = axes[0]
    for index, (label, runs) in enumerate(methods.items()):
        color = f"C{index % 10}"                        # one colour per method across the panels
        for ax, entry in zip(axes, entries):
            per_seed = [run[entry] for run in runs if entry in run]
            if not per_seed:
                continue
            steps, mean, half = mean_and_band(per_seed)
            ax.plot(steps, mean, marker="o", markersize=2.5, color=color, label=f"{label} ({len(per_seed)} seeds)")
            if len(per_seed) > 1:
                ax.fill_between(steps, mean - half, mean + half, color=color, alpha=0.2)
    for ax, entry in zip(axes, entries):
        ax.axhline(1.0, color="black", linestyle="--", linewidth=1)
        ax.set_title(f"validation: {entry}")
        ax.set_xlabel("agent steps")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
    axes[0].set_ylabel("mean score / CBGABI's (same seeds)")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
