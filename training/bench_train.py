"""``python -m training.bench_train`` moved to ``python -m benchmarks.bench_train``."""

import sys

if __name__ == "__main__":
    print("`python -m training.bench_train` moved: run `python -m benchmarks.bench_train`", file=sys.stderr)
    raise SystemExit(2)
