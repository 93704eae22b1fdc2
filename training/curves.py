"""Learning curves with intervals across training seeds, from the ``eval.csv`` files ``taskalloc mappo`` and
``taskalloc train`` write (``taskalloc.evaluation.curves``).

    taskalloc curves --out docs/release_curves.png \\
        "MAPPO + release, Small=models/mappo_release_small_s0/eval.csv,models/mappo_release_small_s1/eval.csv"

Each ``LABEL=EVAL_CSV[,EVAL_CSV …]`` is one method, one eval.csv per training seed: its line is the mean over the
seeds of the greedy policy's validation score divided by CBGABI's on the same seeds, its band the 95 % t-interval
across seeds; one panel per validation entry. An existing PNG is replaced only with ``--overwrite``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from taskalloc.evaluation.curves import plot_bands, read_eval
from taskalloc_env.errors import ConfigError, run_cli


def method_argument(text: str) -> tuple[str, list[Path]]:
    """``LABEL=EVAL_CSV[,EVAL_CSV …]``."""
    label, sep, paths = text.partition("=")
    if not sep or not label or not paths:
        raise ConfigError(f"curve {text!r}: expected LABEL=EVAL_CSV[,EVAL_CSV ...], e.g. \"PPO=runs/s0/eval.csv\"")
    return label, [Path(p) for p in paths.split(",")]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="taskalloc curves", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("methods", nargs="+", metavar="LABEL=EVAL_CSV[,EVAL_CSV ...]",
                        help="a method: its label and one eval.csv per training seed")
    parser.add_argument("--out", type=Path, required=True, help="the PNG to write")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing PNG")
    args = parser.parse_args(argv)
    if args.out.exists() and not args.overwrite:
        raise ConfigError(f"{str(args.out)!r} exists; pass --overwrite to replace it")
    methods = dict(method_argument(item) for item in args.methods)
    plot_bands(args.out, {label: [read_eval(p) for p in paths] for label, paths in methods.items()})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
