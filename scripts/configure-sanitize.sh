#!/usr/bin/env bash
# Configures build-sanitize/: clang, AddressSanitizer and UndefinedBehaviorSanitizer on every
# target, plus the libFuzzer targets. scripts/fuzz.sh and scripts/test.sh --sanitize share it, so
# the sanitized libraries are built once. Installs clang if missing.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/install-deps.sh" fuzz
cmake -S "$root" -B "$root/build-sanitize" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_C_COMPILER=clang \
  -DSEGMATCH_SANITIZE=address,undefined -DSEGMATCH_FUZZ=ON -DSEGMATCH_BUILD_BENCH=OFF >/dev/null
