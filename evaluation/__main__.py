"""``python -m evaluation compare [--scenario NAME] [--episodes N] [--out DIR]`` (also ``python -m policies compare``).

See ``evaluation.compare`` for what the comparison runs and writes.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from evaluation import compare
from taskalloc_env.errors import run_cli


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m evaluation", description="Compare task-allocation policies.")
    sub = parser.add_subparsers(dest="command", required=True)
    compare.add_arguments(sub.add_parser("compare", help="every baseline on the same seeds of a scenario",
                                         description=compare.__doc__.split("\n\n")[0]))
    args = parser.parse_args(argv)
    return compare.run(args)


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
