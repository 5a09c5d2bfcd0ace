#!/usr/bin/env bash
# End-to-end test of --bag (ROS 1 bags written by Debian's python3-rosbag through
# tests/testing/write_bag.py) in `recog eval place`, `recog stream` and `recog load`, against a
# real recogd on a free port: every bad bag is one named error line and nothing is streamed; the
# bundled frames with depth and camera info give metric loops; a bag replays at its own pace. With
# the shared data ($RECOG_SHARED_DATA/places/corridor), the corridor as a bag (JPEG bytes as they
# are, and mono8 pixels) gives exactly the loops of its folder in eval place (100 % precision,
# 81.8 % recall), in stream and in load --verify. Frames are stamped 0.97 s apart: tau_c's 20 s
# then leave out the 20 frames before each, as its 20 frames do for a folder without timestamps.
# Usage: recog_bag_cli_test.sh RECOG_BINARY RECOGD_BINARY PROJECT_DIR
set -u
recog=$1
recogd=$2
project=$3
tmp=$(mktemp -d)
server_pid=
cleanup() {
  [ -n "$server_pid" ] && kill -KILL "$server_pid" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
# shellcheck source=cli_test_lib.sh
source "$(dirname "$0")/cli_test_lib.sh"

images=$project/tests/data/corridor
topic=/camera/image_raw
write_bag() {
  /usr/bin/python3 "$project/tests/testing/write_bag.py" "$@" >"$tmp/write.log" 2>&1 \
    || { echo "FAIL: write_bag.py $*: $(cat "$tmp/write.log")"; exit 1; }
}
if ! /usr/bin/python3 -c "import rosbag, sensor_msgs.msg" 2>/dev/null; then
  echo "FAIL: python3-rosbag and python3-sensor-msgs are needed (scripts/install_deps.sh)"
  exit 1
fi

# The four bundled frames: as JPEG bytes, with a depth image (a plane 2 m away, millimetres) and
# camera info per frame; and the bad bags.
mkdir -p "$tmp/depth"
/usr/bin/python3 -c "
import cv2, numpy
for k in range(4): cv2.imwrite('$tmp/depth/%d.png' % k, numpy.full((384, 512), 2000, numpy.uint16))"
write_bag "$tmp/small.bag" --images "$images" --encoding jpeg --period 0.2 \
  --camera-info-topic /camera/camera_info --camera 500,500,256,192 --depth-images "$tmp/depth"
write_bag "$tmp/yuv.bag" --images "$images" --encoding yuv422
write_bag "$tmp/late_depth.bag" --images "$images" --depth-images "$tmp/depth" --depth-offset 0.05
write_bag "$tmp/unindexed.bag" --images "$images" --unindexed
head -c 100000 "$tmp/small.bag" >"$tmp/truncated.bag"

# Bad bags and flags: one line each, exit 1 (2 for the command line).
expect_error "a bag without --topic lists its image topics" \
  "INVALID_ARGUMENT: --bag needs --topic, one of the bag's image topics: /camera/depth/image_raw (sensor_msgs/Image, 4 messages), $topic (sensor_msgs/CompressedImage, 4 messages)$" \
  "$recog" eval place --bag "$tmp/small.bag" -q
expect_error "an unknown topic lists the bag's topics" \
  "NOT_FOUND: bag '$tmp/small.bag' has no topic /cam (the image topic); its topics: /camera/camera_info (sensor_msgs/CameraInfo, 4 messages), /camera/depth/image_raw (sensor_msgs/Image, 4 messages), $topic" \
  "$recog" eval place --bag "$tmp/small.bag" --topic /cam -q
expect_error "a truncated bag" "DATA_LOSS: bag '$tmp/truncated.bag' is truncated" \
  "$recog" eval place --bag "$tmp/truncated.bag" --topic "$topic" -q
expect_error "an unindexed bag" "DATA_LOSS: .* is unindexed: its recording was not closed .*rosbag reindex" \
  "$recog" eval place --bag "$tmp/unindexed.bag" --topic "$topic" -q
expect_error "an unsupported encoding" \
  "INVALID_ARGUMENT: topic $topic, message at stamp 1000.000000000 of bag '$tmp/yuv.bag': encoding 'yuv422' is not supported" \
  "$recog" eval place --bag "$tmp/yuv.bag" --topic "$topic" -q
expect_error "a frame without depth within the offset" \
  "INVALID_ARGUMENT: bag '$tmp/late_depth.bag': frame 1 (stamp 1000.000000000) of $topic has no depth image on /camera/depth/image_raw within 0.02 s" \
  "$recog" eval place --bag "$tmp/late_depth.bag" --topic "$topic" --depth-topic /camera/depth/image_raw -q
expect_error "a depth topic without the camera" "INVALID_ARGUMENT: --depth-topic and --right-topic need" \
  "$recog" eval place --bag "$tmp/small.bag" --topic "$topic" --depth-topic /camera/depth/image_raw -q
expect_error "--camera and --camera-info-topic" "INVALID_ARGUMENT: give the camera with --camera or --camera-info-topic" \
  "$recog" eval place --bag "$tmp/small.bag" --topic "$topic" --camera-info-topic /camera/camera_info \
  --camera 500,500,256,192 -q
expect_usage_error "--bag with --images" "excludes" "$recog" eval place --bag "$tmp/small.bag" \
  --images "$images" --topic "$topic"
expect_usage_error "--topic without --bag" "requires --bag" "$recog" eval place --images "$images" \
  --topic "$topic"
expect_usage_error "--bag-speed without --bag" "requires --bag" "$recog" load --sequences "$images" \
  --robots 1 --frames 1 --bag-speed 1
expect_error "a depth offset that is not a number" \
  "INVALID_ARGUMENT: BagReadOptions.max_depth_offset = nan: must be finite and >= 0" \
  "$recog" eval place --bag "$tmp/small.bag" --topic "$topic" --max-depth-offset nan -q
for speed in nan -1 inf; do
  expect_error "--bag-speed $speed" "INVALID_ARGUMENT: --bag-speed must be 0 or a positive factor" \
    "$recog" load --bag "$tmp/small.bag" --topic "$topic" --robots 1 --frames 1 --bag-speed "$speed"
done

# The bundled frames from the bag: depth and camera info give 3D points and metric loops.
expect_ok "eval place --bag with depth and camera info" "$recog" eval place --bag "$tmp/small.bag" \
  --topic "$topic" --camera-info-topic /camera/camera_info --depth-topic /camera/depth/image_raw \
  --json -q
json_check "the frames are the bag's, with 3D points" \
  "assert d['frames']==4 and d['layout']=='bag' and 'points' in d['timing_ms'], d"

port=$(free_port)
server=(--server "127.0.0.1:$port")
"$recogd" --listen "127.0.0.1:$port" --data-dir "$tmp/data" --metrics-listen "" --workers 2 \
  >"$tmp/recogd.log" 2>&1 &
server_pid=$!
if ! wait_for_recogd "$server_pid"; then
  echo "FAIL: recogd did not start: $(cat "$tmp/recogd.log")"
  exit 1
fi

# Nothing is streamed from a bad bag: the map is not even created.
for bag in truncated unindexed yuv; do
  expect_error "stream --bag $bag" "recog stream: " "$recog" stream --map "bad-$bag" --create \
    --bag "$tmp/$bag.bag" --topic "$topic" -q "${server[@]}"
done
expect_error "stream --bag with a late depth" "frame 1 (stamp 1000.000000000)" "$recog" stream \
  --map bad-depth --create --bag "$tmp/late_depth.bag" --topic "$topic" \
  --depth-topic /camera/depth/image_raw -q "${server[@]}"
expect_ok "maps list" "$recog" maps list --json "${server[@]}"
json_check "no map was created from a bad bag" "assert d==[], d"
expect_error "load --bag of a truncated bag" "DATA_LOSS" "$recog" load --bag "$tmp/truncated.bag" \
  --topic "$topic" --robots 1 --frames 1 "${server[@]}"

# Metric frames streamed: intrinsics and depth from the bag.
expect_ok "stream --bag with depth" "$recog" stream --map small --create --bag "$tmp/small.bag" \
  --topic "$topic" --camera-info-topic /camera/camera_info --depth-topic /camera/depth/image_raw \
  --json -q "${server[@]}"
/usr/bin/python3 -c "
import json; e=[json.loads(l) for l in open('$tmp/out')]
assert e[-1]['event']=='summary' and e[-1]['frames']==4 and e[-1]['errors']==0, e" \
  && pass || fail "stream --bag --depth-topic streams the 4 frames: $(cat "$tmp/out")"

# The bag's own pace: 4 frames 0.2 s apart take at least 0.6 s at speed 1, half at speed 2.
expect_ok "load --bag --bag-speed 1" "$recog" load --bag "$tmp/small.bag" --topic "$topic" \
  --robots 1 --frames 4 --bag-speed 1 --json -q "${server[@]}"
json_check "at the bag's pace" "assert d['frames_answered']==4 and d['wall_s']>=0.6 and d['options']['bag_speed']==1, d"
expect_ok "load --bag --bag-speed 2" "$recog" load --bag "$tmp/small.bag" --topic "$topic" \
  --robots 1 --frames 4 --bag-speed 2 --json -q "${server[@]}"
json_check "at twice the bag's pace" "assert d['frames_answered']==4 and 0.3<=d['wall_s']<0.6, d"
expect_ok "load --bag with depth --verify" "$recog" load --bag "$tmp/small.bag" --topic "$topic" \
  --camera-info-topic /camera/camera_info --depth-topic /camera/depth/image_raw --robots 2 \
  --frames 4 --verify --json -q "${server[@]}"
json_check "load --bag --verify" "assert d['verified'] and d['frames_answered']==8, d"

# The shared corridor as a bag: exactly its folder's loops, offline, streamed and under load.
shared=${RECOG_SHARED_DATA:-$project/../shared/data}
corridor=$shared/places/corridor
if [ -d "$corridor/images" ]; then
  write_bag "$tmp/corridor.bag" --images "$corridor/images" --encoding jpeg --period 0.97
  write_bag "$tmp/corridor_mono8.bag" --images "$corridor/images" --encoding mono8 --period 0.97 \
    --compression lz4 --reverse
  expect_ok "eval place on the corridor's folder" "$recog" eval place --images "$corridor/images" \
    --ground-truth "$corridor/ground_truth.txt" --json -q
  mv "$tmp/out" "$tmp/folder.json"
  for bag in corridor corridor_mono8; do
    expect_ok "eval place on $bag.bag" "$recog" eval place --bag "$tmp/$bag.bag" --topic "$topic" \
      --ground-truth "$corridor/ground_truth.txt" --json -q
    /usr/bin/python3 -c "
import json
folder, bag = json.load(open('$tmp/folder.json')), json.load(open('$tmp/out'))
loops = lambda d: [(l['query'], l['match'], l['status'], l['inliers']) for l in d['loops']]
assert loops(bag) == loops(folder) and bag['correct'] == 36 and bag['detections'] == 36, (loops(bag), loops(folder))
assert abs(bag['recall'] - 36 / 44) < 1e-9 and bag['precision'] == 1 and bag['layout'] == 'bag', bag
assert bag['loops'][0]['query_file'].startswith('$bag.bag#'), bag['loops'][0]" \
      && pass || fail "eval place --bag $bag.bag gives exactly the folder's loops"
  done
  cp "$tmp/out" "$tmp/eval.json"
  expect_ok "stream --bag the corridor" "$recog" stream --map bag-corridor --create \
    --bag "$tmp/corridor_mono8.bag" --topic "$topic" --json -q "${server[@]}"
  /usr/bin/python3 -c "
import json
events = [json.loads(l) for l in open('$tmp/out')]
streamed = [(e['frame'], e['match']) for e in events if e['event'] == 'loop']
d = json.load(open('$tmp/eval.json'))
evaluated = [(l['query'] - 1, l['match'] - 1) for l in d['loops'] if l['status'] == 'loop_detected']
assert events[-1]['frames'] == 84 and len(evaluated) == 36 and streamed == evaluated, (streamed, evaluated)" \
    && pass || fail "stream --bag finds exactly the loops of eval place"
  expect_ok "load --bag --verify on the corridor" "$recog" load --bag "$tmp/corridor.bag" \
    --topic "$topic" --robots 2 --frames 84 --verify --json -q "${server[@]}"
  json_check "load --bag --verify on the corridor" \
    "assert d['verified'] and d['loops']==72 and all(r['verification']['offline_loops']==36 for r in d['robots']), d"
else
  skip_shared "the shared corridor: $corridor/images not found (set RECOG_SHARED_DATA)"
fi

kill -TERM "$server_pid"
wait "$server_pid"
code=$?
server_pid=
[ "$code" -eq 0 ] && pass || fail "recogd exits 0 on SIGTERM (exit $code): $(tail -5 "$tmp/recogd.log")"

report_and_exit
