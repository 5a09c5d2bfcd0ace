#!/usr/bin/env bash
# End-to-end test of `recog eval sequence --bag` (ROS 1 bags written by Debian's python3-rosbag
# through tests/testing/write_bag.py): a bag of a folder's images, in order, with its camera as
# CameraInfo and --first-frame the number of the folder's first image, gives exactly the folder's
# recognition: the same objects, inliers and pose errors frame by frame and the same summary,
# against the same --truth or --poses. Without shared data: a `recog seqgen objects` sequence
# (frames 000001..000006.png, --first-frame 1) and the flags' errors. With the shared data
# ($RECOG_SHARED_DATA/objects/visp-rbt-cube, its 50 frames and the 11 RoboEarth models): the
# documented run (docs/objects.md) on the folder and on the bag of its PNG files (colour, with
# depth and CameraInfo) agree to the last digit; a bag of their rgb8 pixels finds the cube in the
# same frames (its grey is OpenCV's conversion, not libpng's: docs/cli.md "ROS bags").
# Usage: recog_bag_sequence_test.sh RECOG_BINARY PROJECT_DIR
set -u
recog=$1
project=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# shellcheck source=cli_test_lib.sh
source "$(dirname "$0")/cli_test_lib.sh"

topic=/camera/color/image_raw
info=/camera/color/camera_info
write_bag() {
  /usr/bin/python3 "$project/tests/testing/write_bag.py" "$@" --topic "$topic" \
    --camera-info-topic "$info" >"$tmp/write.log" 2>&1 \
    || { echo "FAIL: write_bag.py $*: $(cat "$tmp/write.log")"; exit 1; }
}
if ! /usr/bin/python3 -c "import rosbag, sensor_msgs.msg" 2>/dev/null; then
  echo "FAIL: python3-rosbag and python3-sensor-msgs are needed (scripts/install_deps.sh)"
  exit 1
fi
# same_recognition FOLDER_JSON BAG_JSON FIRST: the two --json reports agree on everything but the
# frames' names (the bag's k-th frame is frame_<FIRST + k>) and the timings.
same_recognition() {
  /usr/bin/python3 - "$@" <<'EOF'
import json, os, sys
folder, bag = (json.load(open(p)) for p in sys.argv[1:3])
first = int(sys.argv[3])
def strip(d):
    d = dict(d)
    d.pop('timing_ms')
    for k in ('poses', 'size_recall'):
        if k in d: d[k] = {n: v for n, v in d[k].items() if n not in ('csv', 'plot')}
    d['per_frame'] = [{n: v for n, v in f.items() if n not in ('frame', 'total_ms')}
                      for f in d['per_frame']]
    return d
names = ['frame_%04d' % (first + k) for k in range(len(folder['per_frame']))]
assert [f['frame'] for f in bag['per_frame']] == names, [f['frame'] for f in bag['per_frame']]
assert strip(bag) == strip(folder), (strip(bag), strip(folder))
EOF
}

# A seqgen sequence (frames 000001..000006.png) from the bundled frames: a poster in view.
images=$project/tests/data/corridor
mkdir -p "$tmp/object_photos" "$tmp/background_photos"
cp "$images/1.jpg" "$tmp/object_photos/" && cp "$images/20.jpg" "$images/60.jpg" "$tmp/background_photos/"
expect_ok "seqgen objects" "$recog" seqgen objects --object-photos "$tmp/object_photos" \
  --background-photos "$tmp/background_photos" -o "$tmp/objseq" --frames 6 --training-views 1 \
  --min-fraction 0.1 -q
expect_ok "model build of the poster" "$recog" model build --planar "$tmp/objseq/faces/front.png" \
  --width 0.3 --height 0.21 --name synthetic-poster -o "$tmp/poster.robj"
camera=525,525,319.5,239.5
write_bag "$tmp/objseq.bag" --images "$tmp/objseq/images" --encoding png --camera "$camera"
awk '$1 == "frame" && $2 != "000006.png" {
  sub(/[.]png$/, "", $2); line = $2; for (i = 6; i <= 17; ++i) line = line " " $i; print line }' \
  "$tmp/objseq/truth.txt" >"$tmp/objseq-poses.txt"
common=(--models "$tmp/poster.robj" --expect synthetic-poster --json -q)
bag=(--bag "$tmp/objseq.bag" --topic "$topic")

# --truth: the bag's frame_0001.. are the truth's 000001.png..; --track goes the same way too.
expect_ok "eval sequence --images --truth" "$recog" eval sequence "${common[@]}" \
  --images "$tmp/objseq/images" --camera "$camera" --truth "$tmp/objseq/truth.txt" \
  --size-recall "$tmp/size_folder" --track
cp "$tmp/out" "$tmp/folder.json"
expect_ok "eval sequence --bag --truth" "$recog" eval sequence "${common[@]}" "${bag[@]}" \
  --camera-info-topic "$info" --first-frame 1 --truth "$tmp/objseq/truth.txt" \
  --size-recall "$tmp/size_bag" --track
json_check "the bag's frames are scored against the truth and the poster is found" \
  "s = d['size_recall']; assert s['visible_frames'] > 0 and s['found'] > 0, s"
same_recognition "$tmp/folder.json" "$tmp/out" 1 && pass \
  || fail "eval sequence --bag --truth gives exactly the folder's recognition"
cmp -s "$tmp/size_folder.csv" "$tmp/size_bag.csv" && pass || fail "the same size recall CSV"

# --poses with --exclude (frame 000002 / frame_0002), and --camera instead of the camera info.
expect_ok "eval sequence --images --poses" "$recog" eval sequence "${common[@]}" \
  --images "$tmp/objseq/images" --camera "$camera" --poses "$tmp/objseq-poses.txt" \
  --pose-errors "$tmp/poses_folder" --exclude 000002
cp "$tmp/out" "$tmp/folder.json"
expect_ok "eval sequence --bag --poses" "$recog" eval sequence "${common[@]}" "${bag[@]}" \
  --camera "$camera" --first-frame 1 --poses "$tmp/objseq-poses.txt" \
  --pose-errors "$tmp/poses_bag" --exclude frame_0002 --draw "$tmp/draw"
json_check "the bag's frame_0002 is left out, frame_0006 has no pose" \
  "
p = d['poses']
assert d['frames_excluded'] == 1 and d['per_frame'][1]['excluded'], d
assert p['frames_with_pose'] == 4 and p['frames_without_pose'] == 1, p"
same_recognition "$tmp/folder.json" "$tmp/out" 1 && pass \
  || fail "eval sequence --bag --poses gives exactly the folder's recognition"
cmp -s "$tmp/poses_folder.csv" "$tmp/poses_bag.csv" && pass || fail "the same pose error CSV"
[ -f "$tmp/draw/frame_0001.png" ] && pass || fail "--draw names its images after the bag's frames"

# Numbered from 0 (the default), the bag's frames are off by one against the truth and the poses.
expect_error "--truth with the wrong --first-frame" \
  "NOT_FOUND: the truth has no frame numbered 0 (the bag's frame_0000; is --first-frame right?)" \
  "$recog" eval sequence "${common[@]}" "${bag[@]}" --camera-info-topic "$info" \
  --truth "$tmp/objseq/truth.txt" --size-recall "$tmp/size_wrong"
expect_ok "--poses with the wrong --first-frame" "$recog" eval sequence "${common[@]}" "${bag[@]}" \
  --camera "$camera" --poses "$tmp/objseq-poses.txt" --pose-errors "$tmp/poses_wrong"
json_check "frames 1-5 of the bag (images 000002-000006.png) have the wrong poses, frame 0 none" \
  "
p = d['poses']
assert p['frames_with_pose'] == 5 and p['frames_without_pose'] == 1, p
assert p['correct_pose'] < p['found'], p"

# The flags' errors: one line each, exit 1 (2 for the command line).
expect_error "neither --images nor --bag" "INVALID_ARGUMENT: give the frames with --images or --bag" \
  "$recog" eval sequence "${common[@]}" --camera "$camera"
expect_error "--images without --camera" "INVALID_ARGUMENT: --images needs --camera" \
  "$recog" eval sequence "${common[@]}" --images "$tmp/objseq/images"
expect_error "--bag without a camera" \
  "INVALID_ARGUMENT: --bag needs the frames' camera: give --camera or --camera-info-topic" \
  "$recog" eval sequence "${common[@]}" "${bag[@]}"
expect_error "--bag with both cameras" \
  "INVALID_ARGUMENT: --bag needs the frames' camera: give --camera or --camera-info-topic (one of them)" \
  "$recog" eval sequence "${common[@]}" "${bag[@]}" --camera "$camera" --camera-info-topic "$info"
expect_error "--bag without --topic lists its image topics" \
  "INVALID_ARGUMENT: --bag needs --topic, one of the bag's image topics: $topic (sensor_msgs/CompressedImage, 6 messages)$" \
  "$recog" eval sequence "${common[@]}" --bag "$tmp/objseq.bag" --camera "$camera"
expect_error "an unknown topic" "NOT_FOUND: bag '$tmp/objseq.bag' has no topic /cam (the image topic)" \
  "$recog" eval sequence "${common[@]}" --bag "$tmp/objseq.bag" --topic /cam --camera "$camera"
expect_error "a missing bag" "NOT_FOUND" "$recog" eval sequence "${common[@]}" \
  --bag "$tmp/none.bag" --topic "$topic" --camera "$camera"
expect_error "--exclude of a frame not in the bag" "INVALID_ARGUMENT: --exclude: no frame '000002' in --bag" \
  "$recog" eval sequence "${common[@]}" "${bag[@]}" --camera "$camera" --exclude 000002
expect_usage_error "--bag with --images" "excludes" "$recog" eval sequence "${common[@]}" "${bag[@]}" \
  --images "$tmp/objseq/images" --camera "$camera"
expect_usage_error "--first-frame without --bag" "requires --bag" "$recog" eval sequence \
  "${common[@]}" --images "$tmp/objseq/images" --camera "$camera" --first-frame 1
expect_usage_error "a negative --first-frame" "--first-frame" "$recog" eval sequence "${common[@]}" \
  "${bag[@]}" --camera "$camera" --first-frame -1
expect_usage_error "no --depth-topic (eval sequence reads no depth)" "--depth-topic" "$recog" eval \
  sequence "${common[@]}" "${bag[@]}" --camera "$camera" --depth-topic /camera/depth/image_raw

# visp-rbt-cube (docs/objects.md): its folder and the bag of its PNG files agree to the last digit.
shared=${RECOG_SHARED_DATA:-$project/../shared/data}
cube=$shared/objects/visp-rbt-cube
roboearth=$shared/objects/roboearth/models
if [ -f "$cube/poses.txt" ] && [ -d "$roboearth" ]; then
  camera=607.178466796875,607.2342529296875,321.39129638671875,241.91822814941406
  expect_ok "model build of visp-rbt-cube" "$recog" model build --rgbd-recording "$cube" \
    --camera "$camera" --pose "$cube/poses.txt" --views 0,16,33,49 --box 0.085,0.085,0.085 \
    --name visp-rbt-cube -o "$tmp/rbt-cube.robj"
  write_bag "$tmp/cube_png.bag" --images "$cube/images" --encoding png --camera "$camera" \
    --depth-images "$cube/depth" --depth-topic /camera/aligned_depth_to_color/image_raw
  write_bag "$tmp/cube_rgb8.bag" --images "$cube/images" --encoding rgb8 --camera "$camera" \
    --compression lz4 --reverse
  common=(--models "$tmp/rbt-cube.robj" "$roboearth" --expect visp-rbt-cube --poses "$cube/poses.txt" -q)
  expect_ok "eval sequence on visp-rbt-cube's folder" "$recog" eval sequence "${common[@]}" \
    --images "$cube/images" --camera "$camera" --pose-errors "$tmp/cube_folder" --json \
    --exclude color_image_0000,color_image_0016,color_image_0033,color_image_0049
  cp "$tmp/out" "$tmp/folder.json"
  json_check "the folder: the cube in the 46 frames, no wrong object" \
    "assert d['frames'] == 46 and d['detections'] == 46 and d['false_positives'] == 0, d"
  excluded=frame_0000,frame_0016,frame_0033,frame_0049
  expect_ok "eval sequence on visp-rbt-cube's PNG bag" "$recog" eval sequence "${common[@]}" \
    --bag "$tmp/cube_png.bag" --topic "$topic" --camera-info-topic "$info" \
    --pose-errors "$tmp/cube_png" --json --exclude "$excluded"
  same_recognition "$tmp/folder.json" "$tmp/out" 0 && pass \
    || fail "eval sequence --bag on visp-rbt-cube gives exactly the folder's recognition"
  cmp -s "$tmp/cube_folder.csv" "$tmp/cube_png.csv" && pass || fail "the same pose error CSV"
  expect_ok "eval sequence on visp-rbt-cube's rgb8 bag" "$recog" eval sequence "${common[@]}" \
    --bag "$tmp/cube_rgb8.bag" --topic "$topic" --camera-info-topic "$info" \
    --pose-errors "$tmp/cube_rgb8" --json --exclude "$excluded"
  /usr/bin/python3 -c "
import json
folder, bag = json.load(open('$tmp/folder.json')), json.load(open('$tmp/out'))
objects = lambda d: [f['objects'] for f in d['per_frame']]
assert objects(bag) == objects(folder) and bag['detections'] == 46, bag
assert bag['poses']['correct_pose'] == folder['poses']['correct_pose'], (bag['poses'], folder['poses'])" \
    && pass || fail "the rgb8 bag finds the cube in the folder's frames"
else
  skip_shared "visp-rbt-cube: $cube/poses.txt or $roboearth not found (set RECOG_SHARED_DATA)"
fi

report_and_exit
