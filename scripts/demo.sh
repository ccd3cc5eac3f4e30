#!/usr/bin/env bash
# The main job on a fresh Debian 12 machine, end to end:
#   1. builds the project (installing what is missing),
#   2. generates the demo city and drives it twice (sequence 00 maps it, 01 revisits it),
#   3. builds the segment map from 00 with segmatch-mapbuilder,
#   4. starts segmatch-server on a free loopback port,
#   5. replays 01 through the client as a vehicle would, scoring every answer against the
#      exact ground truth, and writes a report folder with plots,
#   6. stops the server.
# Usage: scripts/demo.sh [output folder, default out/demo] [world seed, default 1]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="${1:-$root/out/demo}"
seed="${2:-1}"
bin="$root/build/bin"
mkdir -p "$out/report"
out="$(cd "$out" && pwd)"

step() { printf '\n== [%s] %s\n' "$(date +%H:%M:%S)" "$*"; }

step "1/5 build"
bash "$root/scripts/build.sh" segmatch-sim segmatch-mapbuilder segmatch-mapinfo segmatch-server segmatch-eval

step "2/5 simulate the demo city (two traversals, KITTI layout, exact ground truth)"
"$bin/segmatch-sim" --preset demo --seed "$seed" --out "$out/world" --force

step "3/5 build the map from sequence 00"
"$bin/segmatch-mapbuilder" --input "$out/world/sequences/00" --output "$out/demo-map.sqlite" --name demo --force
"$bin/segmatch-mapinfo" "$out/demo-map.sqlite" --check --png "$out/report/map.png"

step "4/5 start the localization server"
log="$out/server.log"
"$bin/segmatch-server" --map "$out/demo-map.sqlite" --port 0 >"$log" 2>&1 &
server_pid=$!
trap 'kill -TERM $server_pid 2>/dev/null || true; wait $server_pid 2>/dev/null || true' EXIT
port=""
for _ in $(seq 1 600); do
  port="$(sed -n 's/.*listening on [0-9.]*:\([0-9]*\).*/\1/p' "$log" | head -n 1)"
  [ -n "$port" ] && break
  kill -0 $server_pid 2>/dev/null || { cat "$log"; echo "segmatch-server exited" >&2; exit 1; }
  sleep 0.2
done
[ -n "$port" ] || { cat "$log"; echo "segmatch-server did not start listening" >&2; exit 1; }
echo "server pid $server_pid listening on 127.0.0.1:$port"

step "5/5 replay sequence 01 through the server as a vehicle"
"$bin/segmatch-eval" localize --map "$out/demo-map.sqlite" --sim "$out/world" --server "127.0.0.1:$port" \
  --every-m 5 --out "$out/report" | tee "$out/report/queries.txt"

kill -TERM $server_pid
wait $server_pid || { echo "segmatch-server did not exit cleanly" >&2; exit 1; }
trap - EXIT
tail -n 3 "$log"

echo
echo "Demo written to $out"
echo "  world and both trajectories: $out/world/world.png"
echo "  the map:                     $out/report/map.png"
echo "  localizations on the map:    $out/report/trajectory.png"
echo "  P(x) (paper equation 1):     $out/report/px.png"
echo "  error histogram:             $out/report/errors.png"
echo "  every figure:                $out/report/localization.json"
