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
differ=0
for f in "${files[@]}"; do
  if ! clang-format --style=file --dry-run --Werror "$f" >/dev/null 2>&1; then
    echo "format: $f differs from .clang-format (run: bash scripts/format.sh)"
    differ=$((differ + 1))
  fi
done
echo "format: ${#files[@]} files checked with $(clang-format --version), $differ differ"
[ "$differ" = 0 ]
