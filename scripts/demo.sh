#!/usr/bin/env bash
# The main job on a fresh Debian 12 machine: builds the project, generates the demo world
# (two traversals of a simulated city, KITTI layout, exact ground truth) and its pictures.
# Usage: scripts/demo.sh [output folder, default out/demo]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="${1:-$root/out/demo}"
bash "$root/scripts/build.sh" segmatch-sim
"$root/build/bin/segmatch-sim" --preset demo --seed 1 --out "$out" --force
echo
echo "Demo world written to $out"
echo "  picture of the world and both trajectories: $out/world.png"
echo "  one simulated HDL-64E scan:                 $out/scan.png"
