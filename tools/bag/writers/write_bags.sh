#!/bin/bash
# Writes the ROS 2 bag variants of one of the project's image folders, with real writers, and
# checks each one by reading it back (verify_mcap.mjs, verify_rosbag2_sqlite.py).
#
# Usage: write_bags.sh FOLDER OUTDIR [make_manifest.py options...]
#   e.g. write_bags.sh /work/shared/data/places/corridor /work/bags-out/corridor --camera 500,500,256,192
#        write_bags.sh /work/shared/data/objects/visp-rbt-cube /work/bags-out/visp-rbt-cube
# Writes into OUTDIR:
#   mcap_zstd.mcap      chunked, zstd chunks, full summary (indexes, statistics, offsets)
#   mcap_lz4.mcap       chunked, lz4 (frame format) chunks, full summary
#   mcap_nochunk.mcap   messages in the data section, no chunks; summary without chunk indexes
#   mcap_noindex.mcap   zstd chunks, no message indexes and no summary at all
#   sqlite3/            rosbag2 sqlite3 bag: metadata.yaml + NAME_0.db3 (NAME: OUTDIR's name)
# The messages (same CDR bytes in every file) are make_manifest.py's: see its --help for the
# topics and options. OUTDIR/.work/ (manifest, payloads, CDR dump) is removed at the end unless
# KEEP_WORK=1. Needs `npm ci` in this folder once.
set -euo pipefail

if [ $# -lt 2 ]; then
  sed -n '2,16p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
here="$(cd "$(dirname "$0")" && pwd)"
folder="$1"
out="$2"
shift 2
python=/usr/bin/python3 # Debian's, with cv2, numpy and yaml
if [ ! -d "$here/node_modules/@mcap/core" ]; then
  echo "write_bags.sh: run 'npm ci' in $here first" >&2
  exit 1
fi

mkdir -p "$out"
work="$out/.work"
rm -rf "$work"
"$python" "$here/make_manifest.py" "$folder" "$work/manifest" "$@"

node "$here/write_mcap.mjs" "$work/manifest" "$out/mcap_zstd.mcap" --chunk-compression zstd \
  --cdr-dump "$work/cdr"
node "$here/write_mcap.mjs" "$work/manifest" "$out/mcap_lz4.mcap" --chunk-compression lz4
node "$here/write_mcap.mjs" "$work/manifest" "$out/mcap_nochunk.mcap" --no-chunks
node "$here/write_mcap.mjs" "$work/manifest" "$out/mcap_noindex.mcap" --chunk-compression zstd \
  --no-index
"$python" "$here/write_rosbag2_sqlite.py" "$work/cdr" "$out/sqlite3" --name "$(basename "$out")"

if [ "${VERIFY:-1}" = 1 ]; then
  node "$here/verify_mcap.mjs" "$work/manifest" "$out/mcap_zstd.mcap" --compression zstd --chunks yes --index yes
  node "$here/verify_mcap.mjs" "$work/manifest" "$out/mcap_lz4.mcap" --compression lz4 --chunks yes --index yes
  node "$here/verify_mcap.mjs" "$work/manifest" "$out/mcap_nochunk.mcap" --chunks no --index yes
  node "$here/verify_mcap.mjs" "$work/manifest" "$out/mcap_noindex.mcap" --compression zstd --chunks yes --index no
  "$python" "$here/verify_rosbag2_sqlite.py" "$out/sqlite3" "$work/manifest"
fi
[ "${KEEP_WORK:-0}" = 1 ] || rm -rf "$work"
ls -l "$out" "$out/sqlite3"
