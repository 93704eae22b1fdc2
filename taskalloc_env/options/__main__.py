"""``python -m taskalloc_env.options --docs FILE``: rewrite the field tables of FILE from the config's facts."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from taskalloc_env.config import FIELD_GROUPS
from taskalloc_env.errors import run_cli
from taskalloc_env.fields import render_docs


def main(argv: Sequence[str] | None = None) -> int:
    """Rewrite every ``<!-- fields:GROUP -->`` block of the file with its group's table; the rest is kept."""
    parser = argparse.ArgumentParser(prog="python -m taskalloc_env.options", description=main.__doc__)
    parser.add_argument("--docs", type=Path, required=True, help="markdown file with <!-- fields:GROUP --> blocks")
    args = parser.parse_args(argv)
    text = args.docs.read_text(encoding="utf-8")
    new = render_docs(text, FIELD_GROUPS)
    if new != text:
        args.docs.write_text(new, encoding="utf-8")
    print(f"{args.docs}: {'rewritten' if new != text else 'already up to date'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
