#!/usr/bin/env bash
# Reproduces the sweep behind the livox-keyframes preset (docs/how-defaults-were-chosen.md): segmatch-loop
# on ../shared/data/real/hku-loop1 with the odometry-only poses and a 1 m / 2 deg drift bound, over
# L2 threshold x verification resolution x cylinder radius x minimum segment size, one line each:
# true and false loops, and revisit local clouds with a true loop.
# Usage: scripts/hku-sweep.sh [OUT_DIR]   (needs build/bin/segmatch-loop: scripts/build.sh)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
data="$root/../shared/data/real/hku-loop1"
out="${1:-$root/out/hku-sweep}"
bin="$root/build/bin/segmatch-loop"
[ -d "$data" ] || { echo "hku-sweep: $data is absent (the shared data is not part of a clone)" >&2; exit 2; }
[ -x "$bin" ] || { echo "hku-sweep: $bin is missing; run scripts/build.sh first" >&2; exit 2; }
mkdir -p "$out"
total=$((3 * 4 * 4 * 3)); k=0
for l2 in 3 5 10; do for res in 0.6 0.7 0.8 1.0; do for rad in 20 25 30 40; do for mp in 15 20 25; do
  k=$((k + 1))
  cat > "$out/config.json" <<JSON
{"preset": "sparse-keyframes", "local_cloud": {"radius_m": $rad}, "segmenter": {"min_points": $mp},
 "matcher": {"type": "l2", "use_shapes": false, "l2_threshold": $l2}, "verification": {"resolution_m": $res},
 "localizer": {"min_support": 4}}
JSON
  summary=$("$bin" --input "$data" --config "$out/config.json" --odometry "$data/odom_poses.txt" \
      --every-m 1 --exclude-m 25 --history-m 25 --min-inliers 4 --min-confidence 0 \
      --max-drift-m 1 --max-drift-deg 2 --out "$out/run" 2>&1 |
    sed -n 's/^loops: \([0-9]*\) true, \([0-9]*\) false.*/\1 true \2 false/p; s/^revisit local clouds: .*, \([0-9]*\) with a true loop.*/revisit clouds detected \1/p' |
    tr '\n' ' ')
  echo "[$k/$total] l2 $l2 resolution $res radius $rad min_points $mp: $summary"
done; done; done; done
