#!/usr/bin/env bash
# Create .venv and install the project with its training and test extras, and the libraries whose recipes in
# docs/integrations.md run as tests (the integrations extra: SuperSuit, TorchRL, Tianshou).
#
# Torch goes in first, pinned, because a bare "torch" requirement pulls a CUDA build of several GB; pyproject.toml
# keeps a range this pin satisfies, so pip installs nothing more for it. Choose where it comes from with:
#   TORCH_VERSION   (default 2.13.0)
#   TORCH_INDEX_URL (e.g. https://download.pytorch.org/whl/cpu for the CPU-only wheels; default: pip's own index)
# After the install the script checks that no CUDA packages (nvidia-*) came in, and fails if they did.
# A second run with pyproject.toml, this script and the torch choice unchanged does nothing (.venv/.setup-stamp;
# delete it to install again).
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON="${PYTHON:-python3}"
TORCH_VERSION="${TORCH_VERSION:-2.13.0}"
# what the installed .venv was set up from: when none of it changed since, there is nothing to do (the edit-test loop)
STAMP=".venv/.setup-stamp"
wanted=$(cat pyproject.toml scripts/setup.sh | sha256sum | cut -d' ' -f1)-$TORCH_VERSION-${TORCH_INDEX_URL:-}
if [ -x .venv/bin/python ] && [ "$(cat "$STAMP" 2>/dev/null)" = "$wanted" ]; then
  exit 0
fi
if [ ! -x .venv/bin/python ]; then
  "$PYTHON" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
if ! .venv/bin/python -c "import torch" 2>/dev/null; then
  if [ -n "${TORCH_INDEX_URL:-}" ]; then
    .venv/bin/python -m pip install --quiet --index-url "$TORCH_INDEX_URL" "torch==$TORCH_VERSION"
  else
    .venv/bin/python -m pip install --quiet "torch==$TORCH_VERSION"
  fi
fi
.venv/bin/python -m pip install --quiet -e ".[train,dev,integrations,benchmark]"
cuda=$(.venv/bin/python -m pip list --format=freeze 2>/dev/null | grep -i '^nvidia-' || true)
if [ -n "$cuda" ]; then
  echo "setup: CUDA packages were installed (a CUDA build of torch?):" >&2
  echo "$cuda" >&2
  echo "setup: remove .venv and set TORCH_INDEX_URL=https://download.pytorch.org/whl/cpu for the CPU build" >&2
  exit 1
fi
echo "$wanted" > "$STAMP"
