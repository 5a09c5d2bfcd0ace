#!/usr/bin/env bash
# Checks that the README's two commands share one build: after scripts/test.sh, the build that
# scripts/run.sh runs before starting recogd (scripts/build.sh recogd recog, no environment)
# compiles and links nothing, and neither does the whole build of scripts/test.sh run again. CI
# runs it after the tests. Exit 1 with the steps that ran otherwise.
set -euo pipefail
cd "$(dirname "$0")/.."
start=$SECONDS
out=$(env -u RECOG_BUILD_DIR -u RECOG_CMAKE_ARGS bash scripts/build.sh recogd recog 2>&1 &&
  env -u RECOG_BUILD_DIR -u RECOG_CMAKE_ARGS bash scripts/build.sh 2>&1)
# The build-info step runs every time (it rewrites its header only when the commit changes).
steps=$(grep -E '^\[[0-9]+/[0-9]+\] (Building|Linking)' <<<"$out" || true)
if [ -n "$steps" ]; then
  echo "check_no_rebuild: scripts/run.sh's build would redo $(wc -l <<<"$steps") steps after scripts/test.sh:"
  head -20 <<<"$steps"
  exit 1
fi
echo "check_no_rebuild: scripts/run.sh's build after scripts/test.sh: nothing to compile or link ($((SECONDS - start)) s)"
