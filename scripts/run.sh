#!/usr/bin/env bash
# The README's first command: installs the dependencies (Debian 12 packages), builds what serving
# needs in build/ (scripts/build.sh recogd recog; scripts/test.sh builds the tests and benchmarks
# on top of it, compiling nothing twice), and runs the main job: the recognition server, recogd,
# on 127.0.0.1:50051 with its store under ./recog-data, the bundled vocabularies, and the web
# console on http://127.0.0.1:8080/ (Ctrl-C stops it cleanly). Extra arguments go to recogd
# (e.g. --listen 0.0.0.0:50051, --config recogd.yaml); with --console-listen or --config among
# them, the console is theirs to set (recogd's own default is no console).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh --serve
bash scripts/build.sh recogd recog
console=(--console-listen 127.0.0.1:8080)
for arg in "$@"; do
  case $arg in --console-listen* | --config*) console=() ;; esac
done
exec build/bin/recogd "${console[@]}" "$@"
