"""``python -m training.convergence_check`` moved to ``python -m evaluation.convergence``."""

import sys

if __name__ == "__main__":
    print("`python -m training.convergence_check` moved: run `python -m evaluation.convergence`", file=sys.stderr)
    raise SystemExit(2)
