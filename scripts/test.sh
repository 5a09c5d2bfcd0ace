#!/usr/bin/env bash
# The README's test command: installs the dependencies if missing, builds (scripts/build.sh:
# Release, warnings as errors; after scripts/run.sh there is nothing left to compile) and runs
# every test with ctest, then says how many tests skipped and why. Tests that need ../shared/data
# (or $RECOG_SHARED_DATA) skip cleanly without it (with RECOG_REQUIRE_SHARED_DATA=1 they fail).
# Arguments go to ctest: `scripts/test.sh -L unit` runs the unit tests alone (labels: unit,
# integration, data, browser; README, "The two commands").
#
# Environment (used by .ci/run for the sanitizer pass):
#   RECOG_BUILD_DIR   build folder (default: build)
#   RECOG_CMAKE_ARGS  extra CMake arguments (default: none)
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir=${RECOG_BUILD_DIR:-build}
bash scripts/install_deps.sh
bash scripts/build.sh
results="$(cd "$build_dir" && pwd)/ctest-results.xml"
status=0
ctest --test-dir "$build_dir" --output-on-failure -j"$(nproc)" --timeout 600 \
  --output-junit "$results" "$@" || status=$?
python3 scripts/skipped_tests.py "$results"
exit "$status"
