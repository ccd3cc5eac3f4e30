#!/usr/bin/env bash
# Runs every bash block of README.md and docs/*.md that is marked runnable, as it is written there,
# as CTest's DocsRunnableBlocks entry does:
#   tests/docs/runnable_blocks_test.sh SOURCE_DIR BUILD_DIR BIN_DIR [FILE.md...]
# e.g. tests/docs/runnable_blocks_test.sh . build build/bin docs/tools.md
#
# A block is marked by a line `<!-- runnable -->`, `<!-- runnable: fresh -->` or
# `<!-- runnable: fixture -->` right before its ```bash fence (blank lines between are allowed).
# Each block runs with `bash -e` in a scratch folder of its own, under BUILD_DIR, where build/bin is
# BIN_DIR, build/maps is BUILD_DIR/maps (the unpacked regression map) and maps/ is SOURCE_DIR/maps
# (the shipped classifiers):
#   <!-- runnable: fixture -->  exactly one block (the README's quick start): it runs first, in an
#                               empty folder, and must leave the tiny city of seed 3 in out/tiny
#                               and its map in out/tiny/map.sqlite;
#   <!-- runnable -->           the folder starts with a copy of that out/tiny (hard links);
#   <!-- runnable: fresh -->    the folder starts empty.
# With FILE.md arguments only their blocks run, after the fixture block of README.md.
# When this runs as root, each block gets a network namespace of its own (loopback only), so the
# port the docs use (7878) is free whatever else runs on the machine. Background jobs a block
# starts are killed when it ends. Exit 0 if every block passed, 1 otherwise (each failure names
# the file and line of its block and shows its output).
set -euo pipefail
if [ $# -lt 3 ]; then
  sed -n '2,4p' "$0" >&2
  exit 2
fi
source_dir=$(cd "$1" && pwd)
build_dir=$(mkdir -p "$2" && cd "$2" && pwd)
bin_dir=$(cd "$3" && pwd)
shift 3
block_timeout_s=${SEGMATCH_DOCS_BLOCK_TIMEOUT_S:-120}

files=("$@")
if [ ${#files[@]} -eq 0 ]; then
  files=("$source_dir/README.md")
  for f in "$source_dir"/docs/*.md; do files+=("$f"); done
elif ! printf '%s\n' "${files[@]}" | grep -q 'README.md$'; then
  files=("$source_dir/README.md" "${files[@]}")  # for its fixture block
fi

scratch=$build_dir/docs-runnable
rm -rf "$scratch"
mkdir -p "$scratch/blocks"
cleanup() { rm -rf "$scratch"; }
trap cleanup EXIT

# Extract the marked blocks: blocks/N.sh (the block), blocks/N.where (file:line), blocks/N.mode.
awk -v out="$scratch/blocks" '
  FNR == 1 { marker = ""; inblock = 0 }
  inblock {
    if ($0 ~ /^```[[:space:]]*$/) { inblock = 0; close(script); next }
    print > script; next
  }
  /^<!-- runnable(: fresh|: fixture)? -->[[:space:]]*$/ {
    marker = ($0 ~ /fresh/) ? "fresh" : ($0 ~ /fixture/) ? "fixture" : "tiny"; mline = FNR; next
  }
  marker != "" && /^[[:space:]]*$/ { next }
  marker != "" {
    if ($0 ~ /^```bash[[:space:]]*$/) {
      n++; script = out "/" n ".sh"; inblock = 1
      printf "" > script
      print FILENAME ":" FNR > (out "/" n ".where"); close(out "/" n ".where")
      print marker > (out "/" n ".mode"); close(out "/" n ".mode")
    } else {
      print FILENAME ":" mline ": a runnable marker not followed by a ```bash block" > (out "/bad")
    }
    marker = ""
  }
' "${files[@]}"
if [ -f "$scratch/blocks/bad" ]; then
  cat "$scratch/blocks/bad" >&2
  exit 1
fi
count=$(find "$scratch/blocks" -name '*.sh' | wc -l)
fixture_blocks=$(grep -lx fixture "$scratch"/blocks/*.mode 2>/dev/null || true)
if [ "$(printf '%s' "$fixture_blocks" | grep -c .)" -ne 1 ]; then
  echo "expected exactly one block marked <!-- runnable: fixture --> (the README's quick start), found:" \
    "$(for f in $fixture_blocks; do cat "${f%.mode}.where"; done)" >&2
  exit 1
fi
fixture_block=${fixture_blocks%.mode}
echo "[docs] $count runnable blocks"

# A fresh network namespace per block when that is allowed (root), else the machine's own.
netns=()
if unshare -n true 2>/dev/null && command -v ip >/dev/null; then netns=(unshare -n); fi

# The folder every block starts from: the build tree's tools, maps and the shipped models.
prepare() {
  mkdir -p "$1/build"
  ln -s "$bin_dir" "$1/build/bin"
  ln -s "$build_dir/maps" "$1/build/maps"
  ln -s "$source_dir/maps" "$1/maps"
}

run_block() {  # DIR SCRIPT
  local body
  body="set -e
trap 'kill \$(jobs -p) 2>/dev/null || true; wait 2>/dev/null || true' EXIT
$(cat "$2")"
  printf '%s\n' "$body" > "$1/.block.sh"
  if [ ${#netns[@]} -gt 0 ]; then
    (cd "$1" && timeout -k 5 "$block_timeout_s" "${netns[@]}" bash -c 'ip link set lo up && exec bash .block.sh')
  else
    (cd "$1" && timeout -k 5 "$block_timeout_s" bash .block.sh)
  fi
}

# The fixture block first: it makes the tiny city and its map that the other blocks start from.
fixture=$scratch/fixture
prepare "$fixture"
start=$SECONDS
where=$(cat "$fixture_block.where")
if ! run_block "$fixture" "$fixture_block.sh" >"$fixture.log" 2>&1 ||
   [ ! -f "$fixture/out/tiny/map.sqlite" ] || [ ! -d "$fixture/out/tiny/sequences/01" ]; then
  echo "[docs] FAIL  ${where#"$source_dir"/}: the fixture block did not make out/tiny and out/tiny/map.sqlite:"
  sed 's/^/    | /' "$fixture_block.sh"
  tail -n 40 "$fixture.log" | sed 's/^/    > /'
  exit 1
fi
echo "[docs] ok    ${where#"$source_dir"/} (the fixture: $((SECONDS - start)) s)"

failed=0
for ((i = 1; i <= count; i++)); do
  [ "$scratch/blocks/$i" = "$fixture_block" ] && continue
  where=$(cat "$scratch/blocks/$i.where")
  where=${where#"$source_dir"/}
  dir=$scratch/run-$i
  prepare "$dir"
  if [ "$(cat "$scratch/blocks/$i.mode")" = tiny ]; then
    mkdir -p "$dir/out"
    cp -al "$fixture/out/tiny" "$dir/out/tiny"
  fi
  start=$SECONDS
  if run_block "$dir" "$scratch/blocks/$i.sh" >"$dir.log" 2>&1; then
    echo "[docs] ok    $where ($((SECONDS - start)) s)"
  else
    rc=$?
    failed=$((failed + 1))
    echo "[docs] FAIL  $where (exit $rc after $((SECONDS - start)) s):"
    sed 's/^/    | /' "$scratch/blocks/$i.sh"
    echo "    output (last 40 lines):"
    tail -n 40 "$dir.log" | sed 's/^/    > /'
  fi
  rm -rf "$dir" "$dir.log"
done
if [ "$failed" -gt 0 ]; then
  echo "[docs] $failed of $count blocks failed"
  exit 1
fi
echo "[docs] all $count blocks passed"
