#!/usr/bin/env bash
# Coverage-guided fuzzing of every decoder of untrusted input (tests/fuzz): builds the libFuzzer
# targets with clang and -fsanitize=fuzzer,address,undefined into build-sanitize/, then runs each for
# SECONDS, two at a time. Timeouts (10 s an input) and out-of-memory (2 GB) count as crashes; an
# input that crashed is kept under build-sanitize/artifacts/TARGET/ and the run goes on.
# Usage: scripts/fuzz.sh TARGET|all SECONDS      e.g. scripts/fuzz.sh all 30
#        scripts/fuzz.sh --seeds                 rewrite tests/fuzz/corpus/ from the project's writers
# The last line is `fuzz: N targets, E executions, C crashes`; the exit status is 1 if C > 0.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
targets_all=(frame pcd ply kitti poses config map bag)
usage() { echo "usage: scripts/fuzz.sh TARGET|all SECONDS | --seeds   (targets: ${targets_all[*]})" >&2; exit 2; }

[ $# -ge 1 ] || usage
bash "$root/scripts/configure-sanitize.sh"
build="$root/build-sanitize"
jobs="$(nproc 2>/dev/null || echo 2)"

if [ "$1" = "--seeds" ]; then
  cmake --build "$build" -j "$jobs" --target fuzz_make_seeds
  rm -rf "$root/tests/fuzz/corpus"
  "$build/fuzz/fuzz_make_seeds" "$root/tests/fuzz/corpus"
  find "$root/tests/fuzz/corpus" -type f | sort
  exit 0
fi
[ $# -eq 2 ] || usage
seconds="$2"
[[ "$seconds" =~ ^[0-9]+$ ]] && [ "$seconds" -gt 0 ] || { echo "scripts/fuzz.sh: SECONDS must be a positive integer, not '$seconds'" >&2; exit 2; }
if [ "$1" = "all" ]; then
  targets=("${targets_all[@]}")
else
  [[ " ${targets_all[*]} " == *" $1 "* ]] || { echo "scripts/fuzz.sh: unknown target '$1' (targets: ${targets_all[*]})" >&2; exit 2; }
  targets=("$1")
fi
cmake --build "$build" -j "$jobs" $(printf -- '--target fuzz_%s ' "${targets[@]}")

# One target: its own working corpus (the committed seeds stay read-only), a log, the stats.
run_one() {
  local t="$1" work="$build/corpus/$1" artifacts="$build/artifacts/$1/" log="$build/logs/$1.log"
  mkdir -p "$work" "$artifacts" "$(dirname "$log")"
  local status=0 seeds=("$root/tests/fuzz/corpus/$t")
  [ "$t" = frame ] && seeds+=("$root/tests/api/golden")  # the stored golden frames
  "$build/fuzz/fuzz_$t" "$work" "${seeds[@]}" -max_total_time="$seconds" -timeout=10 \
    -rss_limit_mb=2048 -malloc_limit_mb=2048 -print_final_stats=1 -artifact_prefix="$artifacts" >"$log" 2>&1 || status=$?
  local execs
  execs="$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' | tail -1 || true)"
  echo "$t ${execs:-0} $status" >"$build/logs/$t.result"
  printf 'fuzz_%-7s %10s executions in %s s%s\n' "$t" "${execs:-0}" "$seconds" \
    "$([ "$status" -ne 0 ] && echo ", CRASHED (exit $status; log $log, input in $artifacts)")"
}

echo "fuzzing ${#targets[@]} target(s) for $seconds s each, $jobs at a time: ETA $(( (${#targets[@]} + jobs - 1) / jobs * seconds )) s"
rm -f "$build"/logs/*.result
running=0
for t in "${targets[@]}"; do
  run_one "$t" &
  running=$((running + 1))
  if [ "$running" -ge "$jobs" ]; then wait -n || true; running=$((running - 1)); fi
done
wait || true

executions=0 crashes=0
for t in "${targets[@]}"; do
  read -r _ e s <"$build/logs/$t.result"
  executions=$((executions + e))
  [ "$s" -ne 0 ] && crashes=$((crashes + 1))
done
echo "fuzz: ${#targets[@]} targets, $executions executions, $crashes crashes"
[ "$crashes" -eq 0 ]
