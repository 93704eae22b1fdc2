"""``python -m training.evaluate_learned`` moved to ``python -m evaluation.heldout``; this name forwards there."""

from __future__ import annotations

import sys

from taskalloc_env.errors import run_cli

if __name__ == "__main__":
    from evaluation.heldout import main

    print("note: `python -m training.evaluate_learned` is now `python -m evaluation.heldout`", file=sys.stderr)
    raise SystemExit(run_cli(main))
