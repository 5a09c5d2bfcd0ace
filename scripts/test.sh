#!/usr/bin/env bash
# The README's test command: installs the dependencies if missing, builds (scripts/build.sh:
# Release, warnings as errors; after scripts/run.sh there is nothing left to compile) and runs
# every test with ctest, then says how many tests skipped and why. Tests that need ../shared/data
# (or $RECOG_SHARED_DATA) skip cleanly without it (with RECOG_REQUIRE_SHARED_DATA=1 they fail).
# Arguments go to ctest: `scripts/test.sh -L unit` runs the unit tests alone (labels: unit,
# integration, data, browser; README, "The two commands").
#
# Two things overlap to save time on a fresh machine: the test tools (a browser, Python packages,
# nginx, ...: nothing the build needs) are installed while the tests compile, and the benchmarks
# (the target `benchmarks`; no test uses them) compile at the lowest priority while the tests run,
# which leave about a quarter of the CPU idle (servers starting, clients waiting). Their output
# goes to <build>/install_deps.log and <build>/benchmarks.log, printed when they fail.
#
# Environment (used by .ci/run for the sanitizer pass):
#   RECOG_BUILD_DIR   build folder (default: build)
#   RECOG_CMAKE_ARGS  extra CMake arguments (default: none)
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir=${RECOG_BUILD_DIR:-build}

# in_background LOG COMMAND...: runs the command with its output in LOG; `finish` waits for it
# and, when it failed, prints LOG and returns its status.
in_background() {
  local log=$1
  shift
  "$@" >"$log" 2>&1 &
  background_pid=$! background_log=$log
}
finish() {
  local status=0
  wait "$background_pid" || status=$?
  [ "$status" -eq 0 ] || { cat "$background_log" >&2; echo "error: see $background_log" >&2; }
  return "$status"
}

bash scripts/install_deps.sh --serve
mkdir -p "$build_dir"
if [ "$(id -u)" -eq 0 ] || sudo -n true 2>/dev/null; then
  echo "test.sh: the test tools install while the tests compile ($build_dir/install_deps.log)"
  in_background "$build_dir/install_deps.log" bash scripts/install_deps.sh
  build_status=0
  bash scripts/build.sh || build_status=$?
  finish
  [ "$build_status" -eq 0 ] || exit "$build_status"
  tail -n 1 "$build_dir/install_deps.log" # what install_deps did
else
  bash scripts/install_deps.sh # sudo asks for a password: not in the background
  bash scripts/build.sh
fi

echo "test.sh: the benchmarks compile at the lowest priority while the tests run ($build_dir/benchmarks.log)"
in_background "$build_dir/benchmarks.log" nice -n 19 bash scripts/build.sh benchmarks
results="$(cd "$build_dir" && pwd)/ctest-results.xml"
status=0
ctest --test-dir "$build_dir" --output-on-failure -j"$(nproc)" --timeout 600 \
  --output-junit "$results" "$@" || status=$?
python3 scripts/skipped_tests.py "$results"
finish || status=$?
echo "test.sh: benchmarks in $build_dir/bin ($(grep -c '^\[[0-9]*/[0-9]*\] Linking CXX executable bin/bench_' \
  "$build_dir/benchmarks.log" || true) linked now)"
exit "$status"
