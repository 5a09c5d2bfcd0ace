#!/usr/bin/env bash
# The README's first command: installs the dependencies (Debian 12 packages), builds the
# project in build/, and runs the main job: the recognition server, recogd, on 127.0.0.1:50051
# with its store under ./recog-data and the bundled vocabularies (Ctrl-C stops it cleanly).
# Extra arguments go to recogd (e.g. --listen 0.0.0.0:50051, --config recogd.yaml).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
RECOG_CMAKE_ARGS="-DCMAKE_BUILD_TYPE=Release" bash scripts/build.sh
exec build/bin/recogd "$@"
