#!/usr/bin/env bash
# Run the heavy integration recipes of docs/integrations.md (Ray RLlib, AgileRL, BenchMARL), each in its own venv.
# Not part of CI: each stack installs 1.4-2.3 GB and takes about a minute or two to install; the light recipes run in
# tests/test_integrations.py instead.
#
#   bash scripts/heavy_integrations.sh                  # all three
#   bash scripts/heavy_integrations.sh rllib benchmarl  # some of them
#
# For each library, in order:
#   1. a venv in ${HEAVY_VENVS:-$HOME/.cache/taskalloc-heavy}/<lib>, created on the first run and reused later;
#   2. torch==2.13.0 first, as scripts/setup.sh does (TORCH_INDEX_URL, e.g. https://download.pytorch.org/whl/cpu,
#      chooses where it comes from); every later install repeats the pin, so pip can never swap it for a CUDA build;
#   3. the library at the version last tested (PINS below, with the extra pins each one needs);
#   4. this checkout, editable (pip install -e);
#   5. a check that no CUDA packages (nvidia-*) came in;
#   6. docs/integrations/<recipe>.py with OMP_NUM_THREADS=1 (the recipes also call torch.set_num_threads(1)).
# pip's output goes to <venv>.install.log (shown when pip fails), the recipe's to <venv>.log; the script prints the
# versions, the install and run times and the recipe's result (its last line).
# RAY_ADDRESS, if set, makes the RLlib recipe join that Ray cluster instead of starting a local one.
# The exit status is non-zero if any library failed; the others still run.
set -uo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
PYTHON="${PYTHON:-python3}"
HEAVY_VENVS="${HEAVY_VENVS:-$HOME/.cache/taskalloc-heavy}"
TORCH="torch==2.13.0"       # torchvision 0.28.0 (BenchMARL) is the release built for it

declare -A PINS=(
  [rllib]='ray[rllib]==2.60.0'                        # ray[rllib] pins gymnasium==1.2.2 (the project allows it)
  [agilerl]='agilerl==2.58.0 peft==0.21.0'            # agilerl imports peft but installs it only with its llm extras
  [benchmarl]='benchmarl==1.5.2 torchvision==0.28.0'  # unpinned, torchvision 0.29 replaces torch with a CUDA build
)
declare -A RECIPE=([rllib]=rllib_ppo [agilerl]=agilerl_ippo [benchmarl]=benchmarl_task)
declare -A SHOW=(      # distributions whose versions are printed
  [rllib]='ray gymnasium pettingzoo'
  [agilerl]='agilerl pettingzoo gymnasium'
  [benchmarl]='benchmarl torchrl tensordict pettingzoo'
)

now() { date +%s.%N; }
since() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }

install() {  # pip install into $venv, output to $venv.install.log (its tail shown if pip fails)
  "$venv/bin/python" -m pip install "$@" >> "$venv.install.log" 2>&1 && return 0
  tail -n 30 "$venv.install.log" >&2
  return 1
}

run_one() {
  local lib="$1" venv="$HEAVY_VENVS/$1" t rc cuda
  echo "== $lib: venv $venv"
  t=$(now)
  if [ ! -x "$venv/bin/python" ]; then
    "$PYTHON" -m venv "$venv" && install --upgrade pip || return 1
    echo "   venv created in $(since "$t") s"; t=$(now)
  fi
  if [ "$("$venv/bin/python" -c 'import torch; print(torch.__version__.split("+")[0])' 2>/dev/null)" \
       != "${TORCH#torch==}" ]; then
    if [ -n "${TORCH_INDEX_URL:-}" ]; then
      install --index-url "$TORCH_INDEX_URL" "$TORCH" || return 1
    else
      install "$TORCH" || return 1
    fi
  fi
  echo "   $TORCH installed/checked in $(since "$t") s"; t=$(now)
  # shellcheck disable=SC2086  # PINS holds several requirements
  install "$TORCH" ${PINS[$lib]} || return 1
  echo "   ${PINS[$lib]} installed/checked in $(since "$t") s"; t=$(now)
  install "$TORCH" -e "$ROOT" || return 1
  echo "   taskalloc (editable, $ROOT) installed in $(since "$t") s"
  cuda=$("$venv/bin/python" -m pip list --format=freeze 2>/dev/null | grep -i '^nvidia-' || true)
  if [ -n "$cuda" ]; then
    echo "   CUDA packages came in (remove $venv; TORCH_INDEX_URL=https://download.pytorch.org/whl/cpu):" >&2
    echo "$cuda" >&2
    return 1
  fi
  # shellcheck disable=SC2086
  "$venv/bin/python" -c '
import importlib.metadata as md, platform, sys
print("   versions: python", platform.python_version() + ",", ", ".join(f"{d} {md.version(d)}" for d in sys.argv[1:]))
' torch ${SHOW[$lib]} taskalloc
  t=$(now)
  (cd "$ROOT" && OMP_NUM_THREADS=1 MPLBACKEND=Agg "$venv/bin/python" "docs/integrations/${RECIPE[$lib]}.py") \
    > "$venv.log" 2>&1
  rc=$?
  echo "   recipe docs/integrations/${RECIPE[$lib]}.py: exit $rc in $(since "$t") s (output: $venv.log)"
  echo "   result: $(tail -n 1 "$venv.log")"
  return $rc
}

mkdir -p "$HEAVY_VENVS"
start=$(now)
echo "heavy integrations $(date -u +%Y-%m-%dT%H:%MZ), $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg)," \
     "commit $(git -C "$ROOT" rev-parse --short HEAD 2>/dev/null)"
failed=()
for lib in ${@:-rllib agilerl benchmarl}; do
  if [ -z "${PINS[$lib]+x}" ]; then
    echo "unknown library $lib (choose from: ${!PINS[*]})" >&2
    failed+=("$lib")
  elif ! run_one "$lib"; then
    failed+=("$lib")
  fi
done
if [ ${#failed[@]} -gt 0 ]; then
  echo "FAILED: ${failed[*]} (total $(since "$start") s)" >&2
  exit 1
fi
echo "all passed in $(since "$start") s"
