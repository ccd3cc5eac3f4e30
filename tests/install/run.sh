#!/usr/bin/env bash
# The installed product as a user gets it (issue 19): `cmake --install` into a temporary prefix,
# the tools find their models under it, a consumer project builds with find_package(segmatch)
# and PINGs the installed server; then `cpack -G DEB` makes the two packages, the runtime one
# declares its real library dependencies (no PCL, no -dev package), and its unpacked
# segmatch-server answers --version.
# Usage: tests/install/run.sh BUILD_DIR SOURCE_DIR
set -euo pipefail
build="$1" source="$2"
work="$(mktemp -d "${TMPDIR:-/tmp}/segmatch_install_XXXXXX")"
server_pid=""
cleanup() { [ -n "$server_pid" ] && kill "$server_pid" 2>/dev/null; rm -rf "$work"; }
trap cleanup EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

echo "== cmake --install into $work/prefix"
cmake --install "$build" --prefix "$work/prefix" >"$work/install.log" || { cat "$work/install.log"; fail "cmake --install"; }
prefix="$work/prefix"
for f in bin/segmatch-server bin/segmatch-mapbuilder bin/segmatch-query share/segmatch/models/default-rf.yml \
         include/segmatch/api/client.h include/segmatch/core/common/types.h lib/libsegmatch_core.a \
         lib/cmake/segmatch/segmatchConfig.cmake lib/systemd/system/segmatch-server@.service \
         share/segmatch/deploy/haproxy.cfg share/doc/segmatch/README.md share/doc/segmatch/LICENSE \
         share/doc/segmatch/docs/protocol.md share/doc/segmatch/docs/measurements.md; do
  [ -e "$prefix/$f" ] || fail "$f is not installed"
done
version="$("$prefix/bin/segmatch-mapbuilder" --version)"
echo "$version"
grep -q "models: $prefix/share/segmatch/models" <<<"$version" || fail "the installed tool does not look for models under its prefix"

echo "== a consumer project: find_package(segmatch), segmatch::api"
cmake -S "$source/tests/install/consumer" -B "$work/consumer" -DCMAKE_PREFIX_PATH="$prefix" >"$work/consumer.log" 2>&1 ||
  { cat "$work/consumer.log"; fail "configuring the consumer"; }
cmake --build "$work/consumer" -j 2 >>"$work/consumer.log" 2>&1 || { cat "$work/consumer.log"; fail "building the consumer"; }
"$prefix/bin/segmatch-server" --map "$source/maps/tiny-3/map-schema2.sqlite" --port 0 --stats-interval-s 0 \
  >"$work/server.out" 2>"$work/server.log" &
server_pid=$!
for _ in $(seq 100); do grep -q "listening on" "$work/server.out" && break; sleep 0.1; done
port="$(sed -n 's/.*listening on .*:\([0-9]*\)$/\1/p' "$work/server.out")"
[ -n "$port" ] || { cat "$work/server.log"; fail "the installed server did not start"; }
reply="$("$work/consumer/ping_server" 127.0.0.1 "$port")"
echo "consumer: $reply"
[ "$reply" = "PONG 42" ] || fail "the consumer's PING"
kill "$server_pid"; server_pid=""

echo "== cpack -G DEB"
(cd "$build" && cpack -G DEB -B "$work/packages" >"$work/cpack.log" 2>&1) || { cat "$work/cpack.log"; fail "cpack"; }
runtime="$(ls "$work"/packages/segmatch_*.deb)" dev="$(ls "$work"/packages/segmatch-dev_*.deb)"
echo "packages: $(basename "$runtime") ($(du -h "$runtime" | cut -f1)), $(basename "$dev") ($(du -h "$dev" | cut -f1))"
depends="$(dpkg-deb -f "$runtime" Depends)"
echo "runtime Depends: $depends"
grep -q "libsqlite3" <<<"$depends" || fail "the runtime package does not declare libsqlite3 (shlibdeps)"
grep -q "libopencv" <<<"$depends" || fail "the runtime package does not declare OpenCV (shlibdeps)"
! grep -qi "pcl" <<<"$depends" || fail "the runtime package depends on PCL"
! grep -q -- "-dev" <<<"$depends" || fail "the runtime package depends on a -dev package"
runtime_files="$(dpkg-deb -c "$runtime")" dev_files="$(dpkg-deb -c "$dev")"
grep -q "usr/share/segmatch/models/default-rf.yml" <<<"$runtime_files" || fail "the runtime package lacks the model"
grep -q "usr/lib/systemd/system/segmatch-server@.service" <<<"$runtime_files" || fail "the runtime package lacks the unit"
grep -q "usr/include/segmatch/api/client.h" <<<"$dev_files" || fail "the -dev package lacks the headers"
grep -q "usr/lib/cmake/segmatch/segmatchConfig.cmake" <<<"$dev_files" || fail "the -dev package lacks the CMake package"
echo "dev Depends: $(dpkg-deb -f "$dev" Depends)"
dpkg-deb -x "$runtime" "$work/unpacked"
"$work/unpacked/usr/bin/segmatch-server" --version || fail "the unpacked segmatch-server --version"
"$work/unpacked/usr/bin/segmatch-mapbuilder" --version | grep -q "models: $work/unpacked/usr/share/segmatch/models" ||
  fail "the unpacked tools do not find their models"
echo "install, consumer, packages: OK"
