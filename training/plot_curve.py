"""``python -m training.plot_curve`` moved to ``python -m training.curves``."""

import sys

if __name__ == "__main__":
    print("`python -m training.plot_curve` moved: run `python -m training.curves`", file=sys.stderr)
    raise SystemExit(2)
