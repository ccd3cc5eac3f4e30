#!/usr/bin/env bash
# Sets everything up on a fresh Debian 12 machine and runs the whole test suite.
# Usage: scripts/test.sh [ctest options...]
#        scripts/test.sh --sanitize [ctest options...]   the unit, storage, protocol and server
#            suites under AddressSanitizer + UndefinedBehaviorSanitizer (clang, build-sanitize/).
#            Left out: the end-to-end, simulator, map-building, loop and evaluation suites (they
#            take minutes each unsanitized; their decoders and stages are the ones covered here).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
jobs="$(nproc 2>/dev/null || echo 2)"
if [ "${1:-}" = "--sanitize" ]; then
  shift
  bash "$root/scripts/configure-sanitize.sh"
  # segmatch-server too: a server test runs it as its own process (SIGHUP reload); make_server_world
  # builds the server suites' shared world.
  targets=(test_core test_io test_api test_storage test_server make_server_world segmatch-server)
  cmake --build "$root/build-sanitize" -j "$jobs" $(printf -- '--target %s ' "${targets[@]}")
  cd "$root/build-sanitize"
  # Only the suites built above: the others' whole-suite entries and *_NOT_BUILT placeholders
  # would report "Not Run".
  # The server suites' shared world is input data, not code under test: when the optimised build
  # has its builder (CI runs the plain suite first), use it, brought up to date with the sources,
  # instead of building the world under ASan.
  if [ -x "$root/build/tests/make_server_world" ] && [ -z "${SEGMATCH_SERVER_WORLD_TOOL:-}" ]; then
    cmake --build "$root/build" -j "$jobs" --target make_server_world >/dev/null
    export SEGMATCH_SERVER_WORLD_TOOL="$root/build/tests/make_server_world"
  fi
  export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
  # Also left out: Deploy (replicas behind HAProxy: the server code test_server runs),
  # InstallAndPackage (installs and packages every tool, most not built here), PythonClient
  # (Python code; its server is test_server's) and DocsRunnableBlocks (the manual's commands, run
  # with tools not built here).
  ctest --output-on-failure -j "$jobs" -E '^(EndToEnd|RegressionMap|Recordings/RealLocalization|SimulatedLoop|ClosedRoute|HkuLoop|MapBuilderFixture|BagInterop|TrackedDrift|Deploy|InstallAndPackage|PythonClient|DocsRunnableBlocks|.*_NOT_BUILT)$' "$@"
  exit 0
fi
bash "$root/scripts/build.sh"
# The independent ROS 2 bag writer of the interoperability tests (tests/tools/bagwriter, pinned
# by its package-lock.json); without it those tests skip and say why.
if command -v npm >/dev/null 2>&1; then
  (cd "$root/tests/tools/bagwriter" && npm ci --no-audit --no-fund --loglevel=error >/dev/null) ||
    echo "[test] npm ci in tests/tools/bagwriter failed: the bag interoperability tests will skip"
fi
cd "$root/build"
ctest --output-on-failure -j "$jobs" "$@"
