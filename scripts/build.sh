#!/usr/bin/env bash
# Installs the dependencies (if missing), configures and builds into build/.
# Usage: scripts/build.sh [cmake --build targets...]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/install-deps.sh"
jobs="$(nproc 2>/dev/null || echo 2)"
cmake -S "$root" -B "$root/build" -DCMAKE_BUILD_TYPE=Release >/dev/null
if [ $# -gt 0 ]; then
  targets=()
  for t in "$@"; do targets+=(--target "$t"); done
  cmake --build "$root/build" -j "$jobs" "${targets[@]}"
else
  cmake --build "$root/build" -j "$jobs"
fi
