"""``python -m policies compare …``: the comparison command under its first name (it lives in ``evaluation``).

A command entry point, not a module of the library: nothing imports it, so it may reach the evaluation layer above
``policies`` without making the packages depend on each other.
"""

from __future__ import annotations

from evaluation.__main__ import main
from taskalloc_env.errors import run_cli

if __name__ == "__main__":
    raise SystemExit(run_cli(main))
