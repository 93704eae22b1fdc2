"""``python -m training.experiments`` moved to ``python -m evaluation.experiments``; this name forwards there."""

from __future__ import annotations

import sys

from taskalloc_env.errors import run_cli

if __name__ == "__main__":
    from evaluation.experiments import main

    print("note: `python -m training.experiments` is now `python -m evaluation.experiments`", file=sys.stderr)
    raise SystemExit(run_cli(main))
