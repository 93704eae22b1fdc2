"""``python -m training.bench_env`` moved to ``python -m benchmarks.bench_env``."""

import sys

if __name__ == "__main__":
    print("`python -m training.bench_env` moved: run `python -m benchmarks.bench_env`", file=sys.stderr)
    raise SystemExit(2)
