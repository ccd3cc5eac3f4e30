#!/usr/bin/env bash
# Formats every C++ file of the repository with clang-format and the style in .clang-format.
#   bash scripts/format.sh           rewrite the files in place
#   bash scripts/format.sh --check   change nothing; list the files that differ, exit 1 if any (CI)
# Installs clang-format (Debian's) if missing.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
check=0
[ "${1:-}" = "--check" ] && check=1
command -v clang-format >/dev/null || bash scripts/install-deps.sh format
mapfile -t files < <(git ls-files '*.cpp' '*.h')
if [ "$check" = 0 ]; then
  printf '%s\n' "${files[@]}" | xargs -P "$(nproc 2>/dev/null || echo 2)" -n 20 clang-format -i --style=file
  echo "format: ${#files[@]} files formatted with $(clang-format --version)"
  exit 0
fi
# One clang-format a file, as many at once as there are cores; each differing file is named.
differ=$(printf '%s\n' "${files[@]}" | xargs -P "$(nproc 2>/dev/null || echo 2)" -I{} sh -c \
  'clang-format --style=file --dry-run --Werror "{}" >/dev/null 2>&1 || echo "format: {} differs from .clang-format (run: bash scripts/format.sh)"' |
  tee /dev/stderr | wc -l)
echo "format: ${#files[@]} files checked with $(clang-format --version), $differ differ"
[ "$differ" = 0 ]
