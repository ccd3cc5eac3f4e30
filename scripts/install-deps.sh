#!/usr/bin/env bash
# Installs every Debian package the project needs (`fuzz`, `cross`, `format`: also what those scripts need). Idempotent: packages already present are
# skipped, so a second run costs only the dpkg query.
set -euo pipefail

PACKAGES=(
  build-essential cmake pkg-config git
  libeigen3-dev libpcl-dev libopencv-dev libflann-dev libsqlite3-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libcli11-dev nlohmann-json3-dev
  libceres-dev libzstd-dev liblz4-dev
  prometheus-cpp-dev curl
  libcivetweb-dev  # the operator's page (server/src/console.cpp); prometheus-cpp's exposer uses it too
  chromium  # tests/server/console_page_test.cpp opens the operator's page headless (skipped without it)
  file dpkg-dev  # cpack -G DEB (tests/install): ELF detection and dpkg-shlibdeps
  python3-venv python3-numpy python3-setuptools python3-wheel python3-pytest  # python/ and tests/python
  haproxy  # tests/deploy: replicas behind deploy/haproxy (Debian's own haproxy service listens on nothing)
)
# `install-deps.sh fuzz`: also clang and its libFuzzer runtime (scripts/fuzz.sh).
if [ "${1:-}" = "fuzz" ]; then PACKAGES+=(clang libclang-rt-14-dev); fi
# `install-deps.sh cross`: also the aarch64 cross compiler (scripts/cross-aarch64.sh).
if [ "${1:-}" = "cross" ]; then PACKAGES+=(g++-aarch64-linux-gnu); fi
# `install-deps.sh format`: also clang-format (scripts/format.sh; Debian 12's is version 14, whose
# output .clang-format was checked with).
if [ "${1:-}" = "format" ]; then PACKAGES+=(clang-format); fi

# Node.js runs the independent ROS 2 bag writer of the tests (tests/tools/bagwriter). A node and
# npm already on the PATH (e.g. from NodeSource) are used as they are: Debian's npm package would
# conflict with them.
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then PACKAGES+=(nodejs npm); fi

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "[deps] all ${#PACKAGES[@]} packages already installed"
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
echo "[deps] installing: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "[deps] done"
