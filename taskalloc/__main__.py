"""``python -m taskalloc``: the same as the ``taskalloc`` console command."""

from taskalloc.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
