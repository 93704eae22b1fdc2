#!/usr/bin/env bash
# The README's test command: set everything up, lint, run the test suite on both cores.
#   bash scripts/test.sh                 # everything (what CI runs)
#   bash scripts/test.sh -m "not slow"   # the fast subset for the edit-test loop (under a minute)
# Property tests run derandomised (HYPOTHESIS_PROFILE=ci): the same examples every run, so a failure reproduces.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export HYPOTHESIS_PROFILE="${HYPOTHESIS_PROFILE:-ci}"
.venv/bin/ruff check .
.venv/bin/python -m pytest -n 2 -q "$@"
