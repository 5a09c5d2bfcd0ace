#!/usr/bin/env bash
# The README's first command: installs the dependencies (Debian 12 packages), builds the
# project in build/, and runs the main job. Extra arguments go to the main job.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release
cmake --build build -j"$(nproc)"
# Until the server exists (see README), the main job is the offline demo.
exec build/bin/recog demo "$@"
