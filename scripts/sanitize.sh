#!/usr/bin/env bash
# Build the native core (ros_ws/src/iceskate_native) under AddressSanitizer and
# UndefinedBehaviorSanitizer and run with it
#   1. the native tests, tests/iceskate_native, but for the `slow` ones (whole scenes stepped
#      against the Python oracle: their time goes to the uninstrumented oracle), and
#   2. the whole `skate` scene (run_scene, 15 s simulated, with its bag): every period, event and
#      block of the shipped loop and the bag writer's child.
# Exit status 0 only when the build, the tests and the run pass and no sanitizer reported
# anything; non-zero otherwise. A sanitizer report aborts the process it happens in (exit 86),
# and is also looked for at the end, in ASan's report files and in the logged output of every
# step, which catches reports of child processes too (e.g. the forked bag writer of the run).
#
# The sanitized build has its own colcon bases (ros_ws/build-sanitize, install-sanitize,
# log-sanitize; git-ignored): the normal ros_ws/install is untouched, and the sanitized module
# is used only by the Python processes started here (PYTHONPATH). Only our code is instrumented
# (iceskate_native_core, the _kernel module and nanobind's library compiled into it); Pinocchio,
# Boost, Python and numpy are the uninstrumented libraries of the wheels.
#
# Usage: scripts/sanitize.sh     (needs `make setup`; `make sanitize` runs both)
# Environment: ICESKATE_SANITIZE_OUT (directory for the run's outputs and the sanitizer reports,
#   default runs/sanitize), ICESKATE_SANITIZE_DURATION (simulated seconds of the skate run,
#   default 15: the whole scene), ICESKATE_SANITIZE_BUILD_TYPE (default RelWithDebInfo).
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
VENV=$ROOT/.venv
WS=$ROOT/ros_ws
TOOLCHAIN_FILE=$ROOT/scripts/cmake/toolchain.cmake
# Suppressions, one file per tool (their entry types differ and each refuses the other's):
# precise entries for findings in third-party code only; none are needed today. UBSan applies
# suppressions to recoverable checks only: an entry such as `enum:LLT.h` also needs its check
# made recoverable in SAN_FLAGS below (-fsanitize-recover=enum after -fno-sanitize-recover=...).
ASAN_SUPPRESSIONS=$ROOT/scripts/sanitize-asan.supp
UBSAN_SUPPRESSIONS=$ROOT/scripts/sanitize-ubsan.supp
OUT=${ICESKATE_SANITIZE_OUT:-$ROOT/runs/sanitize}
DURATION=${ICESKATE_SANITIZE_DURATION:-15}
# RelWithDebInfo, as -O1 -g1 (below): AddressSanitizer's recommended level (its checks work
# at any level, and -O1 compiles the Pinocchio templates faster than -O2), with
# file:line in the reports' stack traces.
BUILD_TYPE=${ICESKATE_SANITIZE_BUILD_TYPE:-RelWithDebInfo}

log() { printf '[sanitize] %s\n' "$*" >&2; }
die() { printf '[sanitize] error: %s\n' "$*" >&2; exit 1; }

cd "$ROOT"
[ -x "$VENV/bin/python" ] && [ -f "$WS/install/setup.bash" ] || die 'run `make setup` first'
OUT=$(mkdir -p "$OUT" && cd "$OUT" && pwd)
REPORTS=$OUT/reports
rm -rf "$REPORTS" "$OUT/skate"
mkdir -p "$REPORTS"

# One sanitized build at a time in this checkout (e.g. `make sanitize` beside the slow test that
# runs this script): wait for the other one.
mkdir -p "$WS/build-sanitize"
exec 9>"$WS/build-sanitize/.lock"
flock 9

start=$SECONDS

# --- 1. the sanitized build -----------------------------------------------------------------
# -fsanitize=address,undefined   ASan (out-of-bounds, use-after-free, double free, ...) and UBSan
#                                (signed overflow, misaligned or null access, bad shifts, invalid
#                                enum/bool loads, bad downcasts (vptr), ...) in our code;
# -fno-omit-frame-pointer        complete stack traces in the reports (ASan's fast unwinder walks
#                                frame pointers);
# -fno-sanitize-recover=undefined  a UBSan finding aborts the process (by default UBSan prints
#                                and goes on, which would exit 0).
# The same flags for the linker: it links the sanitizer runtimes (libasan, libubsan) into the
# module. -Werror stays on: the build must stay warning-free under these flags too.
SAN_FLAGS='-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined'
# -DEIGEN_MALLOC_ALREADY_ALIGNED=1 (compile only): under -fsanitize=address Eigen switches from
# glibc's malloc (16-byte aligned) to its own aligned allocator, which keeps the malloc'd pointer
# just before the block. Pinocchio's libraries (not instrumented) allocate with plain malloc, so a
# pinocchio::Data they build and our code destroys (or the reverse) would be freed with the other
# scheme: ASan reports a heap-buffer-overflow in Eigen::internal::handmade_aligned_free. This keeps
# our objects' memory layout the same as Pinocchio's (ASan's malloc is 16-byte aligned too).
SAN_CXX_FLAGS="$SAN_FLAGS -DEIGEN_MALLOC_ALREADY_ALIGNED=1"
log "colcon build of iceskate_native under ASan+UBSan ($BUILD_TYPE) into ros_ws/install-sanitize"
(
  # The environment of scripts/bootstrap.sh's build.
  # shellcheck source=scripts/colcon_env.sh
  . "$ROOT/scripts/colcon_env.sh"
  colcon_environment "$VENV" "$TOOLCHAIN_FILE" "$ROOT"
  # As the bootstrap: Pinocchio's C++ side under the pin wheel's cmeel.prefix, ccache (the
  # sanitizer flags are part of ccache's hash, so these objects never mix with the normal ones).
  cmake_args=(-DBUILD_TESTING=OFF -DCMAKE_BUILD_TYPE="$BUILD_TYPE"
    -DCMAKE_PREFIX_PATH="$("$VENV/bin/python" -m cmeel cmake)"
    -DCMAKE_CXX_FLAGS="$SAN_CXX_FLAGS"
    # -g1 (line tables) instead of RelWithDebInfo's -g: the reports need file:line only, and
    # full debug info of the Pinocchio templates makes the cold build ~40 % slower (205 -> 147 s).
    -DCMAKE_CXX_FLAGS_RELWITHDEBINFO='-O1 -g1 -DNDEBUG'
    -DCMAKE_EXE_LINKER_FLAGS="$SAN_FLAGS"
    -DCMAKE_SHARED_LINKER_FLAGS="$SAN_FLAGS"
    -DCMAKE_MODULE_LINKER_FLAGS="$SAN_FLAGS")   # _kernel is a MODULE library (nanobind)
  if [ -x "$VENV/bin/ccache" ]; then
    cmake_args+=(-DCMAKE_CXX_COMPILER_LAUNCHER="$VENV/bin/ccache")
  fi
  cd "$WS"
  # Own build, install and log bases: ros_ws/build, install and log (whose latest build
  # tests/test_lint.py checks for warnings) stay as `make setup` left them.
  colcon --log-base log-sanitize build --symlink-install \
    --base-paths src --build-base build-sanitize --install-base install-sanitize \
    --packages-select iceskate_native \
    --cmake-args "${cmake_args[@]}"
)
build_time=$((SECONDS - start))
log "build: ${build_time} s"

# --- 2. the environment of the sanitized processes --------------------------------------------
# The project environment (venv, ros_ws/install for iceskate_sim & co.), then the sanitized
# iceskate_native before the normal one.
# shellcheck disable=SC1091
. "$ROOT/env.sh"
SAN_SITE=$WS/install-sanitize/iceskate_native/lib/python3.11/site-packages
[ -d "$SAN_SITE/iceskate_native" ] || die "no iceskate_native in $SAN_SITE"
export PYTHONPATH=$SAN_SITE${PYTHONPATH:+:$PYTHONPATH}

# python3 itself is not instrumented, so the ASan runtime must be loaded before everything else
# (it replaces malloc & co.): LD_PRELOAD of the compiler's libasan. Then libstdc++: python3 does
# not link it, so without it ASan starts before libstdc++ is loaded, fails to intercept
# __cxa_throw, and the first C++ exception of the module (a ValueError for bad input) stops the
# process with "CHECK failed: ... real___cxa_throw". libubsan needs no preload: it comes in as a
# dependency of the module (checked below) and has no load-order requirement.
ASAN_LIB=$(g++ -print-file-name=libasan.so)
STDCXX_LIB=$(realpath "$(g++ -print-file-name=libstdc++.so.6)")
[ -f "$ASAN_LIB" ] || die "g++ has no libasan.so ($ASAN_LIB)"
[ -f "$STDCXX_LIB" ] || die "g++ has no libstdc++.so.6 ($STDCXX_LIB)"
# detect_leaks=0: LeakSanitizer would report CPython's own allocations that live until exit
#   (interned objects, module state, numpy/Pinocchio caches); they are not leaks we can fix.
# log_path (ASan): every process writes its reports to $REPORTS/asan.<pid>, checked at the end.
#   GCC's libubsan ignores log_path beside ASan: UBSan reports go to stderr, which every step
#   below tees into $REPORTS/<step>.log, searched at the end.
# exitcode=86: a process stopped by a sanitizer exits 86 (a failing test exits 1).
# print_stacktrace=1 (UBSan): a stack trace with each report; halt_on_error=1: the first report
#   ends the process (also for checks that -fno-sanitize-recover does not cover).
# suppressions: scripts/sanitize-{asan,ubsan}.supp, when they exist.
asan_options="detect_leaks=0:log_path=$REPORTS/asan:exitcode=86"
ubsan_options="print_stacktrace=1:halt_on_error=1:exitcode=86"
if [ -f "$ASAN_SUPPRESSIONS" ]; then asan_options+=":suppressions=$ASAN_SUPPRESSIONS"; fi
if [ -f "$UBSAN_SUPPRESSIONS" ]; then ubsan_options+=":suppressions=$UBSAN_SUPPRESSIONS"; fi
sanitized() {
  LD_PRELOAD="$ASAN_LIB $STDCXX_LIB" ASAN_OPTIONS=$asan_options UBSAN_OPTIONS=$ubsan_options "$@"
}

# The module Python imports is the sanitized one, and it is instrumented.
kernel=$(sanitized python -c 'import iceskate_native._kernel as k; print(k.__file__)')
case $kernel in
  "$SAN_SITE"/iceskate_native/_kernel*.so) log "module: $kernel" ;;
  *) die "python imports $kernel, not the sanitized module under $SAN_SITE" ;;
esac
needed=$(readelf -d "$kernel" | grep NEEDED)
for runtime in libasan libubsan; do
  grep -q "$runtime" <<<"$needed" || die "$kernel does not link $runtime: not a sanitized build"
done

# --- 3. the native tests, then the skate scene -------------------------------------------------
# Each step's output (stdout and stderr) is shown and kept in $REPORTS/<step>.log.
status=0
run_start=$SECONDS
log 'python -m pytest tests/iceskate_native -m "not slow" (sanitized)'
# --capture=sys: pytest captures Python's sys.stdout/stderr only, so a report that native code
# writes to file descriptor 2 reaches the log even when it aborts the test process.
# test_the_module_is_the_built_extension asserts the module is ros_ws/install's: here it is
# install-sanitize's on purpose (checked above), so that one test is left out; test_sanitize.py
# runs this script (it would wait for itself on the lock above).
sanitized python -m pytest tests/iceskate_native -q -p no:cacheprovider --capture=sys -m 'not slow' \
  --deselect tests/iceskate_native/test_kernel.py::test_the_module_is_the_built_extension \
  --ignore tests/iceskate_native/test_sanitize.py \
  2>&1 | tee "$REPORTS/tests.log" || status=$?
tests_time=$((SECONDS - run_start))
log "tests: exit $status, ${tests_time} s"

if [ "$status" = 0 ]; then
  scene_start=$SECONDS
  log "run_scene skate --duration $DURATION (sanitized) into $OUT/skate"
  sanitized run_scene skate --duration "$DURATION" --out "$OUT/skate" --quiet \
    2>&1 | tee "$REPORTS/skate.log" || status=$?
  log "skate: exit $status, $((SECONDS - scene_start)) s"
fi

# --- 4. verdict -------------------------------------------------------------------------------
# A report: ASan's files, or a report's first line in a log (UBSan's "file:line:col: runtime
# error: ...", ASan's/LSan's "==pid==ERROR: ...Sanitizer", the "SUMMARY: ...Sanitizer" line).
pattern=': runtime error: |==[0-9]+==ERROR: [A-Za-z]+Sanitizer|^SUMMARY: [A-Za-z]+Sanitizer'
found=0
for report in "$REPORTS"/asan.*; do
  [ -f "$report" ] || continue
  found=1
  log "sanitizer report $report:"
  cat "$report" >&2
done
for step_log in "$REPORTS"/*.log; do
  if grep -Eq "$pattern" "$step_log"; then
    found=1
    log "sanitizer report in $step_log (shown above):"
    grep -E "$pattern" "$step_log" >&2
  fi
done
if [ "$found" = 1 ]; then
  log "FAILED: a sanitizer reported an error (exit status $status); reports in $REPORTS"
  exit 1
fi
if [ "$status" != 0 ]; then
  log "FAILED: exit status $status, without a sanitizer report (see the output above)"
  exit "$status"
fi
log "OK: no sanitizer report; wall time $((SECONDS - start)) s (build ${build_time} s)"
