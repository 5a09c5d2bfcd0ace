#!/usr/bin/env bash
# The README's test command: installs the dependencies if missing, builds (scripts/build.sh:
# Release, warnings as errors; after scripts/run.sh there is nothing left to compile) and runs
# every test with ctest. Tests that need ../shared/data (or $RECOG_SHARED_DATA) skip cleanly
# without it.
#
# Environment (used by .ci/run for the sanitizer pass):
#   RECOG_BUILD_DIR   build folder (default: build)
#   RECOG_CMAKE_ARGS  extra CMake arguments (default: none)
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir=${RECOG_BUILD_DIR:-build}
bash scripts/install_deps.sh
bash scripts/build.sh
ctest --test-dir "$build_dir" --output-on-failure -j"$(nproc)" --timeout 600
