#!/usr/bin/env bash
# The README's main command: set everything up, then compare the baselines (and the committed learned policy)
# on the default scenario over 20 paired seeds; prints the table and regenerates the committed results/compare/
# (hence --overwrite: the command refuses an existing output folder without it).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/taskalloc compare --scenario default --episodes 20 --out results/compare --overwrite "$@"
