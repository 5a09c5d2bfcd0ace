#!/usr/bin/env bash
# Configures and builds the project with CMake and Ninja: the one build command of scripts/run.sh,
# scripts/test.sh (and so CI) and deploy/docker/Dockerfile. Expects the dependencies to be
# installed (scripts/install_deps.sh).
#
# Usage: bash scripts/build.sh [TARGET ...]   (no target: everything)
#
# The README's two commands (run.sh, then test.sh) build the same configuration in the same
# folder: Release, warnings as errors, tests and benchmarks included. run.sh builds only what
# serving needs (recogd and recog); test.sh builds the rest, so nothing is compiled twice.
# RECOG_CMAKE_ARGS adds to the configuration (a later -D wins over an earlier one), e.g. the
# sanitizer builds of CI or the Dockerfile's build without tests.
#
# Environment:
#   RECOG_BUILD_DIR   build folder (default: build)
#   RECOG_CMAKE_ARGS  extra CMake arguments (default: none)
#   RECOG_JOBS        parallel compile jobs (default: the number of processors)
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir=${RECOG_BUILD_DIR:-build}
# shellcheck disable=SC2086
cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release -DRECOG_WERROR=ON ${RECOG_CMAKE_ARGS:-}
targets=()
[ $# -eq 0 ] || targets=(--target "$@")
cmake --build "$build_dir" -j"${RECOG_JOBS:-$(nproc)}" "${targets[@]}"
