#!/bin/bash
# The acceptance check of ROS 2 bags written by real writers: the shared corridor and
# visp-rbt-cube, written as MCAP (zstd, lz4, no chunks, no index) and as a rosbag2 sqlite3 folder
# by write_bags.sh, must give exactly what their folders give:
#  - `recog eval place --bag` on the corridor: the folder's loops (query, match, status, inliers);
#  - `recog stream --bag` into a recogd: the loops that streaming the folder finds;
#  - `recog eval sequence --bag` on visp-rbt-cube (colour PNG bytes; depth 16UC1 and
#    compressedDepth in the bag, CameraInfo): the folder's recognition, summary line for line.
# Prints one line per comparison (same / DIFFERENT) and exits 1 if any differs.
#
# Usage: tools/bag/writers/check_against_folders.sh [OUTDIR]   (default /tmp/recog-ros2-bags)
# Needs build/bin/recog and build/bin/recogd, `npm ci` in tools/bag/writers, and the shared data
# (RECOG_SHARED_DATA, default ../shared/data). The bags are written once into OUTDIR (~420 MB).
set -uo pipefail
root="$(cd "$(dirname "$0")/../../.." && pwd)"
out=${1:-/tmp/recog-ros2-bags}
shared=${RECOG_SHARED_DATA:-$root/../shared/data}
recog=$root/build/bin/recog
recogd=$root/build/bin/recogd
writers=$root/tools/bag/writers
corridor=$shared/places/corridor
visp=$shared/objects/visp-rbt-cube
variants=(mcap_zstd.mcap mcap_lz4.mcap mcap_nochunk.mcap mcap_noindex.mcap sqlite3)
failed=0
report() {  # report WHAT OK
  if [ "$2" = 0 ]; then echo "same       $1"; else echo "DIFFERENT  $1"; failed=1; fi
}

# The bags: the corridor's JPEG files as CompressedImage (and their pixels as rgb8 Image) stamped
# 0.97 s apart (tau_c's 20 s then leave out 20 frames, as its 20 frames do for the folder); the
# corridor's grey pixels as mono8 Image (the JPEG decoder's own grey, as `recog` reads the files);
# visp-rbt-cube's PNG files and their depth.
[ -f "$out/corridor/mcap_zstd.mcap" ] || VERIFY=0 "$writers/write_bags.sh" "$corridor" \
  "$out/corridor" --camera 500,500,256,192 --image-format both --period 0.97 >/dev/null
[ -f "$out/corridor-mono8/mcap_zstd.mcap" ] || VERIFY=0 "$writers/write_bags.sh" "$corridor" \
  "$out/corridor-mono8" --image-format raw --grey --period 0.97 >/dev/null
[ -f "$out/visp-rbt-cube/mcap_zstd.mcap" ] || VERIFY=0 "$writers/write_bags.sh" "$visp" \
  "$out/visp-rbt-cube" --image-format compressed >/dev/null

work=$(mktemp -d)
server_pid=
cleanup() {
  [ -n "$server_pid" ] && kill "$server_pid" 2>/dev/null && wait "$server_pid"
  rm -rf "$work"
}
trap cleanup EXIT

loops() {  # loops JSON: the eval's loops as lines
  /usr/bin/python3 -c "
import json, sys
d = json.load(open(sys.argv[1]))
for l in d['loops']: print(l['query'], l['match'], l['status'], l['inliers'])
print('correct', d['correct'], 'detections', d['detections'], 'recall %.1f %%' % (100 * d['recall']), 'precision %.1f %%' % (100 * d['precision']))" "$1"
}

# eval place.
"$recog" eval place --images "$corridor/images" --ground-truth "$corridor/ground_truth.txt" \
  --json -q >"$work/folder.json"
loops "$work/folder.json" >"$work/folder.loops"
echo "corridor folder: $(tail -1 "$work/folder.loops")"
for variant in "${variants[@]}"; do
  for bag_topic in corridor:/camera/image_raw/compressed corridor-mono8:/camera/image_raw; do
    bag=$out/${bag_topic%%:*}/$variant topic=${bag_topic#*:}
    "$recog" eval place --bag "$bag" --topic "$topic" \
      --ground-truth "$corridor/ground_truth.txt" --json -q >"$work/bag.json"
    loops "$work/bag.json" >"$work/bag.loops"
    cmp -s "$work/folder.loops" "$work/bag.loops"
    report "eval place  ${bag#"$out"/} $topic: $(tail -1 "$work/bag.loops")" $?
  done
done

# stream, into a recogd of its own.
port=$(/usr/bin/python3 -c "import socket; s = socket.socket(); s.bind(('127.0.0.1', 0)); print(s.getsockname()[1])")
"$recogd" --listen "127.0.0.1:$port" --data-dir "$work/data" --metrics-listen "" \
  >"$work/recogd.log" 2>&1 &
server_pid=$!
for _ in $(seq 100); do
  "$recog" admin health --server "127.0.0.1:$port" >/dev/null 2>&1 && break
  sleep 0.1
done
streamed() {  # streamed MAP ARGS...: the stream's loops as lines
  local map=$1
  shift
  "$recog" stream --map "$map" --create "$@" --json -q --server "127.0.0.1:$port" |
    /usr/bin/python3 -c "
import json, sys
for e in map(json.loads, sys.stdin):
  if e['event'] == 'loop': print(e['frame'], e['match'])
  if e['event'] == 'summary': print('frames', e['frames'])"
}
streamed folder --images "$corridor/images" >"$work/folder.stream"
echo "corridor folder streamed: $(grep -vc frames "$work/folder.stream") loops"
n=0
for variant in "${variants[@]}"; do
  for bag_topic in corridor:/camera/image_raw/compressed corridor-mono8:/camera/image_raw; do
    bag=$out/${bag_topic%%:*}/$variant topic=${bag_topic#*:}
    n=$((n + 1))
    streamed "bag$n" --bag "$bag" --topic "$topic" >"$work/bag.stream"
    cmp -s "$work/folder.stream" "$work/bag.stream"
    report "stream      ${bag#"$out"/} $topic: $(grep -vc frames "$work/bag.stream") loops" $?
  done
done

# eval sequence on visp-rbt-cube (docs/cli.md, "ROS bags").
camera=607.178466796875,607.2342529296875,321.39129638671875,241.91822814941406
"$recog" model build --rgbd-recording "$visp" --camera "$camera" --pose "$visp/poses.txt" \
  --views 0,16,33,49 --box 0.085,0.085,0.085 --name visp-rbt-cube -o "$work/cube.robj" -q >/dev/null
models=("$work/cube.robj" "$shared/objects/roboearth/models")
summary() { grep -v "median" | grep -v "pose errors"; }
"$recog" eval sequence --models "${models[@]}" --images "$visp/images" --camera "$camera" \
  --expect visp-rbt-cube --poses "$visp/poses.txt" \
  --exclude color_image_0000,color_image_0016,color_image_0033,color_image_0049 \
  --pose-errors "$work/folder" -q >"$work/folder.sequence"
echo "visp-rbt-cube folder: $(head -1 "$work/folder.sequence")"
for variant in "${variants[@]}"; do
  "$recog" eval sequence --models "${models[@]}" --bag "$out/visp-rbt-cube/$variant" \
    --topic /camera/image_raw/compressed --camera-info-topic /camera/camera_info \
    --expect visp-rbt-cube --poses "$visp/poses.txt" \
    --exclude frame_0000,frame_0016,frame_0033,frame_0049 --pose-errors "$work/bag" -q \
    >"$work/bag.sequence"
  cmp -s <(summary <"$work/folder.sequence") <(summary <"$work/bag.sequence") &&
    cmp -s <(cut -d, -f2- "$work/folder.csv") <(cut -d, -f2- "$work/bag.csv")
  report "eval sequence visp-rbt-cube/$variant: $(sed -n 2p "$work/bag.sequence" | cut -c1-80)" $?
done
exit $failed
