"""Learning curves from the ``eval.csv`` files that ``taskalloc train`` writes.

    taskalloc curves --out docs/learning_curve.png \\
        "PPO from scratch=models/train_small/eval.csv" "BC + PPO=research/models/train_small_bc/eval.csv"

Each curve is the greedy policy's mean score on the validation seeds (20000 …) against PPO steps (agent
transitions), with the CBGABI mean on the same seeds as a dashed line.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from taskalloc_env.errors import ConfigError, run_cli


def read_curve(path: Path) -> dict[str, list[float]]:
    try:
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise ConfigError(f"cannot read {str(path)!r}: {exc.strerror or exc}") from None
    if not rows or not {"timesteps", "score", "baseline_score"} <= set(rows[0]):
        raise ConfigError(f"{str(path)!r} is not an eval.csv of taskalloc train (no evaluation rows)")
    return {key: [float(r[key]) for r in rows] for key in rows[0]}


def curve_argument(text: str) -> tuple[str, Path]:
    """``LABEL=EVAL_CSV``."""
    label, sep, path = text.partition("=")
    if not sep or not label or not path:
        raise ConfigError(f"curve {text!r}: expected LABEL=EVAL_CSV, e.g. \"PPO=runs/x/eval.csv\"")
    return label, Path(path)


def plot(curves: list[tuple[str, Path]], out: Path, skip_untrained: bool = True) -> None:
    fig, ax = plt.subplots(figsize=(7, 4))
    baseline = None
    for label, path in curves:
        c = read_curve(path)
        points = [(t, s) for t, s in zip(c["timesteps"], c["score"]) if not (skip_untrained and s == 0.0)]
        ax.plot([p[0] for p in points], [p[1] for p in points], marker="o", markersize=3, label=label)
        baseline = c["baseline_score"][0]
    if baseline is not None:
        ax.axhline(baseline, color="black", linestyle="--", linewidth=1, label="CBGABI (same seeds)")
    ax.set_xlabel("PPO steps (agent transitions)")
    ax.set_ylabel("mean score, validation seeds")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="taskalloc curves", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("curves", nargs="+", metavar="LABEL=EVAL_CSV", help="a curve: its label and an eval.csv")
    parser.add_argument("--out", type=Path, required=True, help="the PNG to write")
    args = parser.parse_args(argv)
    plot([curve_argument(item) for item in args.curves], args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
