#!/usr/bin/env bash
# Compiles the core (core/src/<stage>/, every file) for aarch64, the ARM computers vehicles carry, with
# Debian's cross compiler: proof that it builds without x86 intrinsics (segmatch/core/detail/simd.h
# falls back to its scalar lanes there). Objects only: linking would need arm64 builds of
# OpenCV and FLANN. Installs g++-aarch64-linux-gnu if missing. Last line:
#   cross-aarch64: N files compiled for aarch64, F failed
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/install-deps.sh" cross
out="$root/build-aarch64"
inc="$out/include"  # only the header-only libraries' folders: the host's /usr/include would bring x86 glibc headers
rm -rf "$out"
mkdir -p "$inc"
ln -s /usr/include/eigen3/Eigen "$inc/Eigen"
ln -s /usr/include/opencv4/opencv2 "$inc/opencv2"
ln -s /usr/include/flann "$inc/flann"
for h in /usr/include/lz4*.h; do ln -s "$h" "$inc/"; done
jobs="$(nproc 2>/dev/null || echo 2)"
mapfile -t files < <(find "$root/core/src" -name '*.cpp' | sort)
echo "cross-aarch64: compiling ${#files[@]} core files with $(aarch64-linux-gnu-g++ --version | head -1), $jobs at a time"
failed=0
printf '%s\n' "${files[@]}" | xargs -P "$jobs" -I{} sh -c '
  f="{}"; o="'"$out"'/$(basename "$f" .cpp).o"
  aarch64-linux-gnu-g++ -std=c++17 -O2 -ffp-contract=off -DSEGMATCH_SIMD=1 -Wall \
    -I"'"$root"'/core/include" -I"'"$root"'/core/src" -isystem "'"$inc"'" -c "$f" -o "$o" 2>"$o.log" \
    || { echo "FAILED: $f"; cat "$o.log"; exit 255; }' || failed=1
compiled=$(find "$out" -name '*.o' ! -name simd_choice.o | wc -l)
file "$out"/$(basename "${files[0]}" .cpp).o 2>/dev/null | sed 's/^.*: /cross-aarch64: objects are /' || true
# simd.h must have chosen its scalar lanes here.
echo '#include "segmatch/core/detail/simd.h"
static_assert(!SEGMATCH_SIMD_SSE2, "simd.h chose SSE2 on aarch64");' |
  aarch64-linux-gnu-g++ -std=c++17 -DSEGMATCH_SIMD=1 -I"$root/core/include" -x c++ -c - -o "$out/simd_choice.o" ||
  { echo "cross-aarch64: simd.h did not fall back to scalar lanes"; failed=1; }
echo "cross-aarch64: $compiled files compiled for aarch64, $(( ${#files[@]} - compiled )) failed"
exit $failed
