#!/usr/bin/env bash
# Runs the Python client's tests (tests/python/), as CTest's PythonClient entry does:
#   tests/python/run.sh SOURCE_DIR BUILD_DIR BIN_DIR [pytest arguments...]
# e.g. tests/python/run.sh . build build/bin -k protocol
#
# Installs python/ into BUILD_DIR/python-venv offline, as a user would (README in python/):
# numpy, setuptools and wheel are Debian's, seen through --system-site-packages; no registry is
# asked. The venv is made once and reused; the package is reinstalled when a file under python/
# is newer than the last install. Exits 77 (CTest's SKIP_RETURN_CODE) when the machine lacks
# what that needs, naming the apt packages.
set -euo pipefail
if [ $# -lt 3 ]; then
  sed -n '2,4p' "$0" >&2
  exit 2
fi
source_dir=$(cd "$1" && pwd)
build_dir=$(mkdir -p "$2" && cd "$2" && pwd)
bin_dir=$(cd "$3" && pwd)
shift 3

apt_packages="python3-venv python3-numpy python3-setuptools python3-wheel"
skip() {
  echo "SKIPPED: $*"
  echo "  on Debian/Ubuntu: apt-get install -y $apt_packages (and python3-pytest, optional)"
  exit 77
}

# Debian's interpreter first: a pyenv or conda python3 earlier on PATH lacks apt's numpy.
# SEGMATCH_PYTHON names another one.
python=""
for candidate in ${SEGMATCH_PYTHON:-/usr/bin/python3 python3}; do
  if command -v "$candidate" >/dev/null && "$candidate" -c 'import numpy, setuptools, wheel, ensurepip' 2>/dev/null; then
    python=$candidate
    break
  fi
done
[ -n "$python" ] || skip "no ${SEGMATCH_PYTHON:-python3} with numpy, setuptools, wheel and ensurepip (python3-venv)"

venv=$build_dir/python-venv
stamp=$venv/.segmatch-installed
if [ ! -x "$venv/bin/python" ]; then
  rm -rf "$venv"
  if ! "$python" -m venv --system-site-packages "$venv"; then
    rm -rf "$venv"
    skip "$python -m venv failed (python3-venv missing?)"
  fi
fi
if [ ! -f "$stamp" ] || [ -n "$(find "$source_dir/python" -newer "$stamp" -print -quit)" ]; then
  # Built from a copy: pip builds in the folder it is given and would leave build/ and
  # segmatch.egg-info in the source tree.
  staging=$build_dir/python-src
  rm -rf "$staging"
  cp -r "$source_dir/python" "$staging"
  "$venv/bin/pip" install --quiet --disable-pip-version-check --no-index --no-build-isolation "$staging"
  touch "$stamp"
fi

export SEGMATCH_SOURCE_DIR=$source_dir SEGMATCH_BIN_DIR=$bin_dir
export SEGMATCH_TINY3_MAP=$build_dir/maps/tiny-3/map.sqlite  # unpacked from maps/tiny-3/map.sqlite.tar.xz by CMake
export PYTHONDONTWRITEBYTECODE=1  # no __pycache__ in the source tree
"$venv/bin/python" -c 'import segmatch, numpy; print("segmatch", segmatch.__version__, "from", segmatch.__file__, "numpy", numpy.__version__)'
cd "$build_dir"
if "$venv/bin/python" -c 'import pytest' 2>/dev/null; then
  exec "$venv/bin/python" -m pytest -p no:cacheprovider -q -rs "$source_dir/tests/python" "$@"
fi
echo "pytest is not installed (apt-get install -y python3-pytest): running the tests with unittest"
exec "$venv/bin/python" -m unittest discover -s "$source_dir/tests/python" -t "$source_dir/tests/python" "$@"
