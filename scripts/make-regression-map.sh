#!/usr/bin/env bash
# Regenerates the regression map maps/tiny-3/ and its golden answers. Run it when the map
# format or the algorithm changes on purpose, then commit maps/tiny-3/ with a note of why.
#   1. a short simulated tiny city (seed 3): mapping run 00 and revisit 01,
#   2. segmatch-mapbuilder builds maps/tiny-3/map.sqlite from 00 with the shipped classifier,
#   3. segmatch-eval replays 01 against it in-process and its report becomes golden.json.
# tests/eval/regression_test.cpp regenerates the same 01 in-process, replays it with the same
# settings and checks that today's code gives the golden answers.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bin="$root/build/bin"
dest="$root/maps/tiny-3"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
bash "$root/scripts/build.sh" segmatch-sim segmatch-mapbuilder segmatch-mapinfo segmatch-eval
# The same lengths are in tests/eval/regression_test.cpp (kLength00M, kLength01M).
"$bin/segmatch-sim" --preset tiny --seed 3 --length-00-m 250 --length-01-m 200 --no-images --out "$tmp/world"
mkdir -p "$dest"
# Only the stretch of 00 that 01 revisits (its last ~80 m) is mapped, to keep the file small.
"$bin/segmatch-mapbuilder" --input "$tmp/world/sequences/00" --first 245 --output "$dest/map.sqlite" --name tiny-3 \
  --classifier "$root/maps/models/default-rf.yml" --force
"$bin/segmatch-mapinfo" "$dest/map.sqlite" --check --png "$dest/map.png"
"$bin/segmatch-eval" localize --map "$dest/map.sqlite" --sim "$tmp/world" --every-m 10 --quiet --out "$tmp/report"
cp "$tmp/report/localization.json" "$dest/golden.json"
cp "$tmp/report/trajectory.png" "$dest/golden-trajectory.png"
# Stored compressed (4.7 -> 1.6 MB); tests/CMakeLists.txt unpacks it into the build tree.
tar -C "$dest" -cJf "$dest/map.sqlite.tar.xz" map.sqlite
rm "$dest/map.sqlite"
echo "regression map (map.sqlite.tar.xz) and goldens written to $dest"
