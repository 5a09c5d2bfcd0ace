#!/usr/bin/env bash
# The README's first command: installs the dependencies (Debian 12 packages), builds the
# project in build/ (scripts/build.sh: the configuration scripts/test.sh builds too, so the
# README's second command recompiles nothing), and runs the main job: the recognition server,
# recogd, on 127.0.0.1:50051 with its store under ./recog-data and the bundled vocabularies
# (Ctrl-C stops it cleanly). Extra arguments go to recogd (e.g. --listen 0.0.0.0:50051,
# --config recogd.yaml).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
bash scripts/build.sh
exec build/bin/recogd "$@"
