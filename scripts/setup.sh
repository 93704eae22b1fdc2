#!/usr/bin/env bash
# Create .venv and install the project with its training and test extras.
# Torch: the CPU build is pinned first (a bare "torch" requirement would pull a CUDA build of several GB);
# pyproject.toml keeps a range that this pin satisfies, so pip installs nothing more for it.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
  "$PYTHON" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
if ! .venv/bin/python -c "import torch" 2>/dev/null; then
  .venv/bin/python -m pip install --quiet "torch==2.13.0"
fi
.venv/bin/python -m pip install --quiet -e ".[train,dev]"
