#!/bin/bash
# Writes the committed ROS 2 bag fixtures (tests/data/bags/, see its README.md) from the synthetic
# sequence of synth_frames.py, with the same real writers as write_bags.sh, and checks each one.
# Usage: make_fixtures.sh [OUTDIR]   (default: tests/data/bags of this repository)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="$(realpath -m "${1:-$here/../../../tests/data/bags}")"
python=/usr/bin/python3
if [ ! -d "$here/node_modules/@mcap/core" ]; then
  echo "make_fixtures.sh: run 'npm ci' in $here first" >&2
  exit 1
fi
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
mkdir -p "$out"

"$python" "$here/synth_frames.py" "$work/frames"
"$python" "$here/make_manifest.py" "$work/frames" "$work/manifest" --image-format both \
  --depth-format both --start 1700000000 --period 0.1
# 32 KiB chunks: the 30 messages spread over several chunks.
mcap() { node "$here/write_mcap.mjs" "$work/manifest" "$out/$1" --chunk-size 32768 "${@:2}"; }
mcap fixture.mcap --chunk-compression zstd --cdr-dump "$work/cdr"
mcap fixture_lz4.mcap --chunk-compression lz4
mcap fixture_noindex.mcap --chunk-compression zstd --no-index
mcap fixture_nochunk.mcap --no-chunks
mcap fixture_cdr_be.mcap --chunk-compression zstd --big-endian
"$python" "$here/write_rosbag2_sqlite.py" "$work/cdr" "$out/fixture_sqlite3" --name fixture

verify() { node "$here/verify_mcap.mjs" "$work/manifest" "$out/$1" "${@:2}"; }
verify fixture.mcap --compression zstd --chunks yes --index yes
verify fixture_lz4.mcap --compression lz4 --chunks yes --index yes
verify fixture_noindex.mcap --compression zstd --chunks yes --index no
verify fixture_nochunk.mcap --chunks no --index yes
verify fixture_cdr_be.mcap --compression zstd --chunks yes --index yes
"$python" "$here/verify_rosbag2_sqlite.py" "$out/fixture_sqlite3" "$work/manifest"
du -ab "$out" | sort -k2
